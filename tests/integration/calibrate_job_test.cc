// The calibrate job as an operator runs it, on its failure paths: a job that would drive the
// stage out of its travel is refused before the first frame; a calibration that fails leaves
// the previous file in effect, byte for byte; a file that cannot be written loses nothing that
// was measured.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "insitu/calib/calibration.h"
#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

std::string ReadAll(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

Result<job::Report> RunCalibrate(const fs::path& out, const std::vector<std::string>& sets) {
  return testing::RunShippedJob("calibrate.yaml", sets, (out / "job").string());
}

fs::path Fresh(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("insitu_calibrate_job_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(CalibrateJob, StageOutOfTravelIsRefusedBeforeMeasuring) {
  const fs::path dir = Fresh("travel");
  // The default world's stage travels -20..20 mm.
  auto report = RunCalibrate(dir, {"height.z_end_mm=30", "output.calibration=" +
                                                             (dir / "machine.yaml").string()});
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(report.status().message().find("height.z_end_mm"), std::string::npos)
      << report.status().message();
  EXPECT_NE(report.status().message().find("stage travel [-20, 20]"), std::string::npos)
      << report.status().message();
  EXPECT_FALSE(fs::exists(dir / "machine.yaml"));
}

TEST(CalibrateJob, FailedCalibrationLeavesThePreviousInEffect) {
  const fs::path dir = Fresh("failed");
  const fs::path previous = dir / "machine.yaml";
  fs::copy_file(fs::path(INSITU_SOURCE_DIR) / "calib/as_designed.yaml", previous);
  const std::string before = ReadAll(previous);
  // Intrinsics come out at ~0.07 px RMS; a 0.01 px requirement cannot be met.
  auto report = RunCalibrate(dir, {"intrinsics.max_rms_px=0.01", "height.enabled=false",
                                   "output.calibration=" + previous.string()});
  ASSERT_FALSE(report.ok());
  EXPECT_NE(report.status().message().find("RMS"), std::string::npos)
      << report.status().message();
  EXPECT_EQ(ReadAll(previous), before);
  EXPECT_FALSE(fs::exists(previous.string() + ".tmp"));
  // The report of the failed run says why.
  const std::string json = ReadAll(dir / "job" / "report.json");
  EXPECT_NE(json.find("\"ok\": false"), std::string::npos) << json;
}

TEST(CalibrateJob, UnwritableOutputKeepsTheMeasurement) {
  const fs::path dir = Fresh("unwritable");
  std::ofstream(dir / "not_a_folder") << "x";
  const fs::path target = dir / "not_a_folder" / "machine.yaml";
  auto report = RunCalibrate(dir, {"height.enabled=false", "output.calibration=" +
                                                               target.string()});
  ASSERT_FALSE(report.ok());
  const std::string message = report.status().message();
  EXPECT_NE(message.find("not_a_folder"), std::string::npos) << message;
  const fs::path copy = dir / "job" / "calibration.yaml";
  EXPECT_NE(message.find(copy.string()), std::string::npos) << message;
  // The copy is a complete calibration that loads.
  auto loaded = calib::LoadCalibration(copy.string());
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_GT(loaded->camera.fx, 4000.0);
}

}  // namespace
}  // namespace insitu
