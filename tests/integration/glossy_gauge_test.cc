// A glossy step gauge measured end to end (a calibration and an accuracy scan, about a minute
// on two cores). On the default cell the camera looks 32 deg off the direction the gauge's top
// faces mirror the pointer into: a fine-turned face (a 2 deg lobe) sends the camera nothing of
// its specular light, a bead-blasted one (15 deg) a share that grows towards the camera's
// side of the scan, so the stripe's brightness changes with x and the lobe's flank adds light
// beside the diffuse line. The operator's jobs are the matte part's: calibrate, then the
// accuracy job on the gauge. The bar is the calibration issue's: every 1 mm bin's mean height
// within +-0.05 mm; the 80 mm length within +-0.08 mm, as on the perturbation test's cells.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

TEST(GlossyGauge, MeasuresWithinTheMattePartsBar) {
  const fs::path out = fs::temp_directory_path() / "insitu_glossy_gauge";
  fs::remove_all(out);
  // Bead-blasted stainless: a third of the light scattered, half mirrored in a 15 deg lobe
  // (docs/simulator.md, world.part.specular).
  const std::vector<std::string> glossy = {"world.part.albedo=0.3", "world.part.specular=0.5",
                                           "world.part.specular_lobe_deg=15"};
  const std::string cal = (out / "machine.yaml").string();
  auto calibrated = testing::QuickCalibrate(cal, (out / "calibrate").string(), glossy);
  ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  ASSERT_TRUE(calibrated->ok) << calibrated->error;
  std::vector<std::string> sets = glossy;
  for (const char* s : {"scan.line_spacing_mm=1.0", "scan.x_start_mm=-9.5", "scan.x_end_mm=9.5"}) {
    sets.emplace_back(s);
  }
  sets.push_back("machine.calibration=" + cal);
  auto report =
      testing::RunShippedJob("accuracy_step_gauge.yaml", sets, (out / "accuracy").string());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_TRUE(report->ok) << report->error;
  auto& m = report->metrics;
  std::printf(
      "glossy gauge: binned %.4f mm, rms %.4f mm, length error %+.4f mm, points %g, "
      "columns two-peak %g, bad shape %g, saturated %g\n",
      m["height_error_max_abs_binned_mm"], m["height_error_rms_mm"], m["length_error_mm"],
      m["points"], m["columns_two_peaks"], m["columns_bad_shape"], m["columns_saturated"]);
  for (const char* step : {"3mm", "5mm", "10mm", "15mm"}) {
    EXPECT_LT(std::abs(m[std::string("height_error_mean_mm_step_") + step]), 0.05) << step;
  }
  EXPECT_LT(m["height_error_max_abs_binned_mm"], 0.05);
  EXPECT_LT(std::abs(m["length_error_mm"]), 0.08);
}

}  // namespace
}  // namespace insitu
