#include "insitu/calib/calibration.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace insitu::calib {
namespace {

namespace fs = std::filesystem;

std::string WriteTemp(const std::string& name, const std::string& text) {
  const fs::path p = fs::temp_directory_path() / name;
  std::ofstream(p) << text;
  return p.string();
}

const char* kMinimal = R"(format: insitu-calibration
version: 1
camera:
  model: VH-5MG
  width_px: 2448
  height_px: 2048
  fx: 4347.8
  fy: 4347.8
  cx: 1223.5
  cy: 1023.5
galvo:
  pivot_height_mm: 355
  camera_from_galvo:
    rotation_rodrigues_rad: [0.1, -0.2, 0.05]
    translation_mm: [1, 2, 300]
)";

TEST(Calibration, ShippedAsDesignedFileLoads) {
  auto set = LoadCalibration(std::string(INSITU_SOURCE_DIR) + "/calib/as_designed.yaml");
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_EQ(set->camera.width_px, 2448);
  EXPECT_EQ(set->produced_by, "as_designed");
  // Drawing: camera at (-180, 0, 300) looking at the origin: the origin is on the axis.
  const Eigen::Vector3d origin_in_camera = set->galvo.camera_from_galvo * Eigen::Vector3d::Zero();
  EXPECT_NEAR(origin_in_camera.x(), 0.0, 1e-9);
  EXPECT_NEAR(origin_in_camera.y(), 0.0, 1e-9);
  EXPECT_NEAR(origin_in_camera.z(), std::hypot(180.0, 300.0), 1e-9);
}

TEST(Calibration, SaveThenLoadRoundTrips) {
  auto set = LoadCalibration(WriteTemp("cal_min.yaml", kMinimal));
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  const std::string out = (fs::temp_directory_path() / "cal_roundtrip.yaml").string();
  ASSERT_TRUE(SaveCalibration(*set, out).ok());
  auto again = LoadCalibration(out);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_TRUE(again->galvo.camera_from_galvo.isApprox(set->galvo.camera_from_galvo, 1e-10));
  EXPECT_DOUBLE_EQ(again->camera.fx, set->camera.fx);
}

// A measured head goes through the file unchanged (12 significant digits), and the file's
// correction inverts its own landing map.
TEST(Calibration, MeasuredHeadRoundTripsAndInverts) {
  auto set = LoadCalibration(std::string(INSITU_SOURCE_DIR) + "/calib/as_designed.yaml");
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_FALSE(set->head.measured);
  EXPECT_DOUBLE_EQ(set->head.model.design.focal_length_mm, 255.0);
  HeadCalibration& h = set->head;
  h.measured = true;
  h.measured_by = "test";
  h.model.built.focal_length_mm = 256.2;
  h.model.built.ftheta_c3 = 0.03;
  h.model.x_zero_offset_mrad = 0.2;
  h.pointer.lateral_colour_pct = -0.3;
  auto table = optics::GridTable::Make({-50, 0, 50}, {-50, 50},
                                       {{0.001, 0}, {0, 0.002}, {-0.001, 0}, {0, 0}, {0.003, 0}, {0, 0}});
  ASSERT_TRUE(table.ok());
  h.residual_mm = *table;
  const std::string out = (fs::temp_directory_path() / "cal_head.yaml").string();
  ASSERT_TRUE(SaveCalibration(*set, out).ok());
  auto again = LoadCalibration(out);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  const HeadCalibration& g = again->head;
  EXPECT_TRUE(g.measured);
  EXPECT_DOUBLE_EQ(g.model.built.focal_length_mm, 256.2);
  EXPECT_DOUBLE_EQ(g.model.built.ftheta_c3, 0.03);
  EXPECT_DOUBLE_EQ(g.pointer.lateral_colour_pct, -0.3);
  EXPECT_EQ(g.residual_mm.values().size(), 6u);
  const Eigen::Vector3d target(42.0, -17.0, 3.0);
  Eigen::Vector3d cmd, spot;
  ASSERT_TRUE(g.MarkCommandFor(target, &cmd));
  ASSERT_TRUE(g.MarkSpot(cmd, &spot));
  EXPECT_NEAR((spot - target).norm(), 0.0, 1e-6);
  EXPECT_GT((cmd - target).norm(), 0.1);  // the 0.47 % scale alone moves it 0.2 mm
}

TEST(Calibration, RefusesOtherVersionsUnknownKeysAndMissingKeys) {
  std::string text = kMinimal;
  auto bad_version = LoadCalibration(
      WriteTemp("cal_v2.yaml", text.replace(text.find("version: 1"), 10, "version: 2")));
  ASSERT_FALSE(bad_version.ok());
  EXPECT_NE(bad_version.status().message().find("version"), std::string::npos);

  std::string typo = kMinimal;
  typo.replace(typo.find("  fy:"), 5, "  fxx: 1\n  fy:");
  auto unknown = LoadCalibration(WriteTemp("cal_typo.yaml", typo));
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("camera.fxx"), std::string::npos)
      << unknown.status().message();
  EXPECT_NE(unknown.status().message().find("cal_typo.yaml"), std::string::npos);

  auto missing = LoadCalibration("/nonexistent/cal.yaml");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

TEST(Calibration, UndistortInvertsProject) {
  auto set = LoadCalibration(WriteTemp("cal_min2.yaml", kMinimal));
  ASSERT_TRUE(set.ok());
  CameraIntrinsics cam = set->camera;
  cam.k1 = -0.06;
  cam.k2 = 0.08;
  cam.p1 = 2e-4;
  const Eigen::Vector3d p(40.0, -30.0, 330.0);
  const Eigen::Vector2d px = cam.Project(p);
  const auto n = cam.Undistort({px});
  EXPECT_NEAR(n[0].x(), p.x() / p.z(), 1e-9);
  EXPECT_NEAR(n[0].y(), p.y() / p.z(), 1e-9);
}

TEST(Calibration, BinningMapsPixelCentres) {
  CameraIntrinsics cam;
  cam.width_px = 2448;
  cam.height_px = 2048;
  cam.fx = cam.fy = 4000;
  cam.cx = 1223.5;
  cam.cy = 1023.5;
  const CameraIntrinsics b = cam.Binned(2);
  const Eigen::Vector3d p(10, 20, 300);
  const Eigen::Vector2d full = cam.Project(p), binned = b.Project(p);
  EXPECT_NEAR(binned.x(), (full.x() + 0.5) / 2 - 0.5, 1e-9);
  EXPECT_NEAR(binned.y(), (full.y() + 0.5) / 2 - 0.5, 1e-9);
}

TEST(Calibration, CameraMismatchIsRefusedWithTheReason) {
  CameraIntrinsics cal;
  cal.model = "VH-5MG";
  cal.serial = "A1";
  cal.width_px = 2448;
  cal.height_px = 2048;
  EXPECT_TRUE(CheckCameraMatches(cal, "VH-5MG", "A1", 2448, 2048).ok());
  const Status serial = CheckCameraMatches(cal, "VH-5MG", "B2", 2448, 2048);
  EXPECT_NE(serial.message().find("serial"), std::string::npos);
  EXPECT_FALSE(CheckCameraMatches(cal, "acA2500", "A1", 2448, 2048).ok());
  EXPECT_FALSE(CheckCameraMatches(cal, "VH-5MG", "A1", 2592, 1944).ok());
  cal.serial = "";  // as-designed numbers fit any unit of the model
  EXPECT_TRUE(CheckCameraMatches(cal, "VH-5MG", "B2", 2448, 2048).ok());
}

}  // namespace
}  // namespace insitu::calib
