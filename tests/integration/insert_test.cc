// The insert job (seed 000 sec. 3.3.4, Table 1) on a machine calibrated through the calibrate
// job, with the insert where the operator happened to put it: thickness, three edge lengths
// (tip-radius corrected) and hole diameter against the nominal values.
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

class InsertJob : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const fs::path dir = fs::temp_directory_path() / "insitu_insert_test";
    fs::remove_all(dir);
    calibration_ = (dir / "machine.yaml").string();
    // The insert lies within x = +-10 mm and z = 0..5 mm, inside the quick calibration.
    auto report = testing::QuickCalibrate(calibration_, (dir / "calibrate").string());
    ASSERT_TRUE(report.ok()) << report.status().ToString();
  }
  static std::string calibration_;
};
std::string InsertJob::calibration_;

// Bound 0.04 mm per dimension (the shipped jobs reach the 0.03 mm: 0.012 to 0.023 mm
// over four placements): the edge points scatter ~0.018 mm rms (speckle moves each
// half-brightness crossing), correlated over a speckle grain (~0.2 mm), so each fitted edge
// carries ~0.005 mm, and an edge length, which depends on all three edges (3.5x an outward
// shift of the edges), ~0.015 mm; the ends sit ~0.005 mm outside the true edges on average
// (+0.017 mm on an edge length); and the lateral scale comes from the calibrated camera pose,
// which differs between calibrations by a few micrometres over the insert (this test's
// coarser calibration: up to +0.027 mm here).
TEST_F(InsertJob, DimensionsOfAnInsertPlacedAnywhere) {
  const fs::path out = fs::temp_directory_path() / "insitu_insert_test" / "insert";
  auto report = testing::RunShippedJob(
      "insert.yaml",
      {"machine.calibration=" + calibration_, "world.part.position_mm=[-3.0, 2.0]",
       "world.part.rotation_deg=41", "scan.x_start_mm=-13", "scan.x_end_mm=7"},
      out.string());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  auto& m = report->metrics;
  for (const char* key : {"insert_thickness_error_mm", "insert_edge_1_error_mm",
                          "insert_edge_2_error_mm", "insert_edge_3_error_mm",
                          "insert_hole_diameter_error_mm"}) {
    EXPECT_LT(std::abs(m[key]), 0.04) << key;
    std::printf("%s %+.4f\n", key, m[key]);
  }
  // Without the tip-radius correction the edges are the sharp triangle's: 0.29 mm longer.
  EXPECT_NEAR(m["insert_edge_1_raw_mm"] - m["insert_edge_1_mm"],
              2.0 * (std::sqrt(3.0) - 1.0) * 0.2, 1e-9);
  EXPECT_TRUE(fs::exists(out / "insert.png"));
  EXPECT_TRUE(fs::exists(out / "insert_edges.csv"));
}

// No insert on the stage: the job says so instead of measuring the plate.
TEST_F(InsertJob, EmptyStageIsNotAnInsert) {
  auto report = testing::RunShippedJob(
      "insert.yaml",
      {"machine.calibration=" + calibration_, "world.part.kind=none", "scan.line_spacing_mm=1.0"},
      (fs::temp_directory_path() / "insitu_insert_test" / "empty").string());
  ASSERT_FALSE(report.ok());
  EXPECT_NE(report.status().message().find("is an insert in the scanned area"),
            std::string::npos)
      << report.status().message();
}

}  // namespace
}  // namespace insitu
