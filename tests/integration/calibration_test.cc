// Camera calibration on the simulated machine: chessboard views through the camera -> OpenCV
// intrinsics; pointer spots at known galvo positions -> camera pose in the galvo frame.
// Compared with the simulator's true camera.
#include <cmath>
#include <memory>

#include <gtest/gtest.h>

#include "insitu/calib/camera_calibration.h"
#include "insitu/sim/world.h"
#include "insitu/vision/targets.h"

namespace insitu {
namespace {

sim::WorldOptions BoardWorld() {
  sim::WorldOptions w;
  w.part.kind = "none";
  w.board.present = true;
  w.board.inner_cols = 9;
  w.board.inner_rows = 6;
  w.board.square_mm = 8.0;
  w.board.margin_mm = 5.0;
  w.stage.z_mm = -20.0;  // stage lowered so the held board clears the plate
  // Hand-held views: tilted up to ~25 deg, spread over the field.
  w.board.poses = {
      {0, 0, 0, 0, 0, 0},        {-40, -35, 5, 20, -10, 5},  {40, -35, 0, 20, 15, -8},
      {-40, 35, 8, -20, -15, 10}, {40, 35, 3, -22, 12, -5},  {0, -50, 10, 25, 0, 15},
      {0, 50, -5, -25, 5, -15},  {-55, 0, 0, 5, -25, 3},    {55, 0, 5, -5, 25, -3},
      {10, 10, 8, 12, 18, 30},   {-10, -10, -8, -15, -18, -30}, {20, -15, 2, 0, 28, 12},
      {-25, 20, 4, 28, 10, -20}, {30, 10, -6, -12, -28, 25}, {-5, -25, 6, 18, -22, -35},
  };
  return w;
}

// Intrinsics from hand-held views. Corners are found to better than 0.1 px here (noise
// ~1 DN on ~150 DN edges), so the reprojection RMS must be < 0.2 px. The parameters must agree
// with the true camera within 4 of the one-sigma uncertainties OpenCV derives from the
// residuals (plus 0.5 px / 0.1 % for the corner detector's small systematic bias).
TEST(Calibration, IntrinsicsFromChessboardViewsMatchTheTrueCamera) {
  sim::WorldOptions world = BoardWorld();
  sim::SimWorld w(world);
  ASSERT_TRUE(w.SetExposure(300000).ok());
  std::vector<std::vector<Eigen::Vector2d>> views;
  vision::ChessboardOptions board{world.board.inner_cols, world.board.inner_rows};
  for (int k = 0; k < w.board_pose_count(); ++k) {
    ASSERT_TRUE(w.PlaceBoard(k).ok());
    auto frame = w.Grab();
    ASSERT_TRUE(frame.ok());
    auto corners = vision::FindChessboard({frame->bytes.data(), frame->width, frame->height,
                                           frame->stride_bytes(), frame->bit_depth},
                                          board);
    if (corners.ok()) views.push_back(*corners);
  }
  EXPECT_GE(views.size(), 10u);  // a few poses put part of the board out of view
  calib::BoardGeometry geometry{world.board.inner_cols, world.board.inner_rows,
                                world.board.square_mm};
  const calib::IntrinsicsSummary s = calib::CalibrateIntrinsics(
      views, geometry, world.camera.width_px, world.camera.height_px, calib::IntrinsicsOptions{});
  ASSERT_TRUE(s.ok) << s.message;
  const sim::CameraModel truth(world.camera);
  std::printf("views %d rms %.3f px coverage %.2f fx %.2f (true %.2f) cx %.2f (%.2f) cy %.2f "
              "(%.2f) k1 %.4f k2 %.4f\n",
              s.views, s.rms_px, s.coverage, s.intrinsics.fx, truth.fx(), s.intrinsics.cx,
              truth.cx(), s.intrinsics.cy, truth.cy(), s.intrinsics.k1, s.intrinsics.k2);
  ASSERT_GE(s.stddev.size(), 4u);
  std::printf("sigma fx %.2f cx %.2f cy %.2f px\n", s.stddev[0], s.stddev[2], s.stddev[3]);
  EXPECT_LT(s.rms_px, 0.2);
  EXPECT_NEAR(s.intrinsics.fx, truth.fx(), 4 * s.stddev[0] + 0.001 * truth.fx());
  EXPECT_NEAR(s.intrinsics.cx, truth.cx(), 4 * s.stddev[2] + 0.5);
  EXPECT_NEAR(s.intrinsics.cy, truth.cy(), 4 * s.stddev[3] + 0.5);
}

TEST(Calibration, TooFewViewsAndPoorCoverageAreRefused) {
  calib::BoardGeometry geometry;
  std::vector<std::vector<Eigen::Vector2d>> views(3);
  for (auto& v : views) {
    for (int j = 0; j < geometry.inner_rows; ++j)
      for (int i = 0; i < geometry.inner_cols; ++i) v.emplace_back(1000 + 10 * i, 1000 + 10 * j);
  }
  calib::IntrinsicsSummary s = calib::CalibrateIntrinsics(views, geometry, 2448, 2048, {});
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.message.find("too few views"), std::string::npos) << s.message;
  views.resize(10, views[0]);
  s = calib::CalibrateIntrinsics(views, geometry, 2448, 2048, {});
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.message.find("coverage"), std::string::npos) << s.message;
}

TEST(Calibration, BoardNotInViewIsNotFound) {
  sim::WorldOptions world = BoardWorld();
  world.board.poses = {{400, 0, 0, 0, 0, 0}};  // far outside the camera's view
  sim::SimWorld w(world);
  ASSERT_TRUE(w.SetBinning(2).ok());
  ASSERT_TRUE(w.PlaceBoard(0).ok());
  auto frame = w.Grab();
  auto corners = vision::FindChessboard({frame->bytes.data(), frame->width, frame->height,
                                         frame->stride_bytes(), frame->bit_depth},
                                        {world.board.inner_cols, world.board.inner_rows});
  EXPECT_EQ(corners.status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace insitu

namespace insitu {
namespace {

// Pointer spots on the stage plate at two stage heights, at known galvo positions. Speckle
// (contrast 0.2, grain ~2.6 px) on a spot of sigma ~1.5 px covering ~4 grains moves its
// centroid by ~0.2 * 1.5 / sqrt(4) ~ 0.15-0.2 px ~ 0.015 mm rms; shot noise is far smaller.
// With 50 spots over 80 x 80 x 10 mm the pose error averages down further. Bounds: residual
// < 0.03 mm rms (2x the speckle estimate), the camera centre within 0.5 mm and the rotation
// within 0.02 deg of the true mount.
TEST(Calibration, PointerSpotsGiveTheCameraPoseInTheGalvoFrame) {
  sim::WorldOptions world;
  world.part.kind = "none";
  sim::SimWorld w(world);
  ASSERT_TRUE(w.SetExposure(500).ok());
  std::vector<calib::GalvoSpot> spots;
  for (double z : {0.0, 10.0}) {
    ASSERT_TRUE(w.MoveStage(z).ok());
    w.StopPointer();
    auto dark = w.Grab();
    for (double x = -40; x <= 40; x += 20) {
      for (double y = -40; y <= 40; y += 20) {
        const Eigen::Vector3d p(x, y, z);
        ASSERT_TRUE(w.StartPointerLine(p, p, 1.0).ok());
        w.Advance(0.005);
        auto lit = w.Grab();
        auto spot = vision::FindSpot({lit->bytes.data(), lit->width, lit->height,
                                      lit->stride_bytes(), lit->bit_depth},
                                     {dark->bytes.data(), dark->width, dark->height,
                                      dark->stride_bytes(), dark->bit_depth},
                                     {});
        ASSERT_TRUE(spot.ok()) << spot.status().ToString();
        spots.push_back({p, spot->center});
      }
    }
  }
  const sim::CameraModel truth(world.camera);
  calib::CameraIntrinsics cam;
  cam.width_px = world.camera.width_px;
  cam.height_px = world.camera.height_px;
  cam.fx = truth.fx();
  cam.fy = truth.fy();
  cam.cx = truth.cx();
  cam.cy = truth.cy();
  cam.k1 = world.camera.k1;
  cam.k2 = world.camera.k2;
  cam.p1 = world.camera.p1;
  cam.p2 = world.camera.p2;
  const calib::AlignmentSummary a = calib::AlignCameraToGalvo(spots, cam, {});
  ASSERT_TRUE(a.ok) << a.message;
  const Eigen::Vector3d centre = a.camera_from_galvo.inverse().translation();
  const Eigen::AngleAxisd rot_err(a.camera_from_galvo.linear() *
                                  truth.camera_from_world().linear().transpose());
  std::printf("spots %d rms %.4f px %.4f mm, centre error %.3f mm, rotation error %.4f deg\n",
              a.spots, a.rms_px, a.rms_mm, (centre - truth.center_in_world()).norm(),
              rot_err.angle() * 180 / M_PI);
  EXPECT_LT(a.rms_mm, 0.03);
  EXPECT_LT((centre - truth.center_in_world()).norm(), 0.5);
  EXPECT_LT(rot_err.angle() * 180 / M_PI, 0.02);
}

TEST(Calibration, SpotsOnALineAreSingular) {
  std::vector<calib::GalvoSpot> spots;
  for (int i = 0; i < 8; ++i) spots.push_back({{-40.0 + 10 * i, 0.0, 0.0}, {100.0 + 50 * i, 500}});
  calib::CameraIntrinsics cam;
  cam.width_px = 2448;
  cam.height_px = 2048;
  cam.fx = cam.fy = 4348;
  cam.cx = 1224;
  cam.cy = 1024;
  const calib::AlignmentSummary a = calib::AlignCameraToGalvo(spots, cam, {});
  EXPECT_FALSE(a.ok);
  EXPECT_NE(a.message.find("singular"), std::string::npos) << a.message;
  spots.resize(3);
  EXPECT_NE(calib::AlignCameraToGalvo(spots, cam, {}).message.find("too few"), std::string::npos);
}

}  // namespace
}  // namespace insitu
