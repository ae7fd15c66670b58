#include "insitu/sim/world.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

namespace insitu::sim {
namespace {

WorldOptions SmallWorld() {
  WorldOptions w;
  w.part.kind = "plane";
  return w;
}

double Mean(const Frame& f) {
  double s = 0;
  for (int v = 0; v < f.height; ++v)
    for (int u = 0; u < f.width; ++u) s += f.at(u, v);
  return s / (static_cast<double>(f.width) * f.height);
}

// A frame takes its exposure, then its bytes cross the camera's link (118 MB/s: GigE less its
// framing): 612 x 512 binned 8-bit pixels, 313,344 bytes, 2.655 ms.
TEST(SimWorld, GrabAdvancesTheClockByTheExposureAndTheLink) {
  SimWorld w(SmallWorld());
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.SetExposure(20000).ok());
  const double t0 = w.now_s();
  auto f = w.Grab();
  ASSERT_TRUE(f.ok());
  EXPECT_NEAR(w.now_s() - t0, 0.02 + 612.0 * 512.0 / 118e6, 1e-12);
  EXPECT_EQ(f->width, 2448 / 4);
  EXPECT_EQ(f->height, 2048 / 4);
}

// A region of interest: the frame holds the band's rows, exactly those of the whole frame, says
// where it lies, and crosses the link in the band's share of the time.
TEST(SimWorld, ARegionIsTheWholeFramesBandAndTravelsFaster) {
  SimWorld whole(SmallWorld()), band(SmallWorld());
  for (SimWorld* w : {&whole, &band}) {
    ASSERT_TRUE(w->SetBinning(4).ok());
    ASSERT_TRUE(w->SetExposure(20000).ok());
  }
  ASSERT_TRUE(band.SetRegion(800, 400).ok());  // binned rows 200..300
  EXPECT_EQ(band.SetRegion(2000, 100).code(), StatusCode::kOutOfRange);
  const double t0 = band.now_s();
  auto a = whole.Grab();
  auto b = band.Grab();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(b->offset_y, 200);
  EXPECT_EQ(b->height, 100);
  EXPECT_NEAR(band.now_s() - t0, 0.02 + 612.0 * 100.0 / 118e6, 1e-12);
  for (int v = 0; v < b->height; v += 7) {
    for (int u = 0; u < b->width; u += 13) ASSERT_EQ(b->at(u, v), a->at(u, v + 200)) << u << "," << v;
  }
}

// Ambient light scales with exposure (linear sensor, no stripe): doubling the exposure
// doubles the mean signal above the ~0.5 DN rounding floor, within shot noise.
TEST(SimWorld, AmbientSignalIsLinearInExposure) {
  WorldOptions o = SmallWorld();
  o.light.ambient_lux = 3000;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.SetExposure(10000).ok());
  const double m1 = Mean(*w.Grab());
  ASSERT_TRUE(w.SetExposure(20000).ok());
  const double m2 = Mean(*w.Grab());
  EXPECT_GT(m1, 5.0);
  EXPECT_NEAR(m2 / m1, 2.0, 0.05);
}

TEST(SimWorld, StripeAppearsOnlyWhileThePointerRuns) {
  SimWorld w(SmallWorld());
  ASSERT_TRUE(w.SetBinning(2).ok());
  auto dark = w.Grab();
  EXPECT_EQ(w.last_truth().samples, 0);
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  w.Advance(0.005);
  auto lit = w.Grab();
  EXPECT_GT(w.last_truth().samples, 1000);
  const int max_dark = *std::max_element(dark->bytes.begin(), dark->bytes.end());
  const int max_lit = *std::max_element(lit->bytes.begin(), lit->bytes.end());
  EXPECT_GT(max_lit, max_dark + 50);
}

TEST(SimWorld, SaturationClipsAtFullScale) {
  WorldOptions o = SmallWorld();
  o.scan_head.pointer.power_mw = 5.0;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(2).ok());
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  auto f = w.Grab();
  EXPECT_EQ(*std::max_element(f->bytes.begin(), f->bytes.end()), 255);
}

TEST(SimWorld, TwelveBitFramesUseSixteenBitSamples) {
  WorldOptions o = SmallWorld();
  o.camera.bit_depth = 12;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  auto f = w.Grab();
  EXPECT_EQ(f->bytes.size(), static_cast<size_t>(f->width) * f->height * 2);
  int mx = 0;
  for (int v = 0; v < f->height; ++v)
    for (int u = 0; u < f->width; ++u) mx = std::max(mx, f->at(u, v));
  EXPECT_GT(mx, 255);
  EXPECT_LE(mx, 4095);
}

// The 15 mm step hides the plate behind it from the camera: some beam samples are occluded.
TEST(SimWorld, TallStepOccludesTheStripeBehindIt) {
  WorldOptions o;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.StartPointerLine({12.0, -30, 0}, {12.0, 30, 0}, 5000).ok());
  (void)w.Grab();
  EXPECT_GT(w.last_truth().occluded_samples, w.last_truth().samples / 2);
}

TEST(SimWorld, RefusesCommandsOutsideItsLimits) {
  SimWorld w(SmallWorld());
  EXPECT_EQ(w.StartPointerLine({0, -90, 0}, {0, 30, 0}, 5000).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.StartPointerLine({0, 0, 40}, {0, 30, 40}, 5000).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.MoveStage(25.0).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.SetExposure(-5).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.SetBinning(3).code(), StatusCode::kInvalidArgument);
}

TEST(SimWorld, SameSeedSameFrame) {
  SimWorld a(SmallWorld()), b(SmallWorld());
  for (SimWorld* w : {&a, &b}) {
    ASSERT_TRUE(w->SetBinning(4).ok());
    ASSERT_TRUE(w->StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  }
  EXPECT_EQ(a.Grab()->bytes, b.Grab()->bytes);
}

TEST(WorldOptions, ValidateNamesTheField) {
  WorldOptions o;
  o.camera.exposure_ms = -1;
  const Status st = o.Validate();
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("camera: exposure_ms"), std::string::npos) << st.message();
}

}  // namespace
}  // namespace insitu::sim
