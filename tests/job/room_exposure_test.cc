// The exposure for the operator's chessboard under the room's light (job/room_exposure.h): a
// camera whose frames show a synthetic board, its gray levels proportional to the exposure (a
// linear sensor) and clipped at full scale.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "insitu/core/frame.h"
#include "insitu/hw/camera.h"
#include "job/room_exposure.h"

namespace insitu::job {
namespace {

// 10 x 7 squares of 36 px (9 x 6 inner corners) on a light-gray card in a 640 x 480 frame. At
// `white_at_300ms` the white squares read that many gray levels at 300 ms (before clipping);
// black squares 8 % of white (printed black), the card 60 %.
class BoardCamera : public hw::Camera {
 public:
  // Below `min_white_seen` gray levels of white the board is lost in the card (too little
  // contrast for its corners).
  explicit BoardCamera(double white_at_300ms, bool board = true, double min_white_seen = 0.0)
      : white_at_300ms_(white_at_300ms), board_(board), min_white_seen_(min_white_seen) {}
  hw::CameraInfo info() const override {
    hw::CameraInfo i;
    i.model = "test";
    i.sensor_width_px = 640;
    i.sensor_height_px = 480;
    return i;
  }
  Status SetExposure(double us) override {
    if (fail_) return DeviceError("camera unplugged");
    exposure_ms_ = us * 1e-3;
    return Status::Ok();
  }
  Status SetGain(double) override { return Status::Ok(); }
  Status SetBinning(int) override { return Status::Ok(); }
  double exposure_ms() const { return exposure_ms_; }
  void Fail() { fail_ = true; }

 protected:
  Result<Frame> GrabFrame() override {
    Frame f;
    f.width = 640;
    f.height = 480;
    f.bytes.assign(640 * 480, 0);
    const double white = white_at_300ms_ * exposure_ms_ / 300.0;
    const auto level = [](double g) { return static_cast<uint8_t>(std::clamp(g, 0.0, 255.0)); };
    const int sq = 36, u0 = 140, v0 = 114;
    for (int v = 0; v < 480; ++v) {
      for (int u = 0; u < 640; ++u) {
        double g = 0.6 * white;
        const int i = (u - u0) / sq, j = (v - v0) / sq;
        if (board_ && white >= min_white_seen_ && u >= u0 && v >= v0 && i < 10 && j < 7) {
          g = (i + j) % 2 == 0 ? 0.08 * white : white;
        }
        f.bytes[static_cast<size_t>(v) * 640 + u] = level(g);
      }
    }
    return f;
  }

 private:
  double white_at_300ms_;
  bool board_;
  double min_white_seen_;
  double exposure_ms_ = 0.0;
  bool fail_ = false;
};

const vision::ChessboardOptions kBoard{9, 6};

// Settled: the white squares within 15 % of 65 % of full scale (the settling band).
void ExpectSettled(const RoomExposure& r, double white_at_300ms) {
  const double white = std::min(255.0, white_at_300ms * r.exposure_ms / 300.0) / 255.0;
  EXPECT_NEAR(white, 0.65, 0.65 * 0.15) << r.exposure_ms << " ms";
  EXPECT_NEAR(r.white_fraction, white, 1.0 / 255.0);
  EXPECT_TRUE(r.note.empty()) << r.note;
}

TEST(RoomExposure, ABoardThatClipsIsExposedShorter) {
  BoardCamera camera(700.0);  // white squares clipped at 300 ms in a bright room
  auto r = ExposeForBoard(camera, 300.0, 30.0, 3000.0, kBoard);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ExpectSettled(*r, 700.0);
  EXPECT_EQ(camera.exposure_ms(), r->exposure_ms);  // the camera is left at it
  EXPECT_GE(r->shots, 2);
}

TEST(RoomExposure, ADimBoardIsExposedLonger) {
  BoardCamera camera(40.0);  // a dark room: white squares at 16 % of full scale
  auto r = ExposeForBoard(camera, 300.0, 30.0, 3000.0, kBoard);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ExpectSettled(*r, 40.0);
  EXPECT_GT(r->exposure_ms, 900.0);
}

// Clipped at 300 ms and at 100 ms, lost at 33 ms: the exposure is sought between the two
// (a third or three times would go back and forth between them).
TEST(RoomExposure, ABoardLostDarkAndClippedBrightIsSoughtBetween) {
  BoardCamera camera(1000.0, true, 120.0);
  auto r = ExposeForBoard(camera, 300.0, 30.0, 3000.0, kBoard);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ExpectSettled(*r, 1000.0);
}

TEST(RoomExposure, NoBoardInViewKeepsTheStartAndSaysSo) {
  BoardCamera camera(150.0, /*board=*/false);
  auto r = ExposeForBoard(camera, 300.0, 30.0, 3000.0, kBoard);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->exposure_ms, 300.0);
  EXPECT_EQ(camera.exposure_ms(), 300.0);
  EXPECT_EQ(r->white_fraction, 0.0);
  EXPECT_NE(r->note.find("not seen"), std::string::npos) << r->note;
}

TEST(RoomExposure, ACameraFaultIsTheError) {
  BoardCamera camera(150.0);
  camera.Fail();
  auto r = ExposeForBoard(camera, 300.0, 30.0, 3000.0, kBoard);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(r.status().message().find("board exposure"), std::string::npos);
}

}  // namespace
}  // namespace insitu::job
