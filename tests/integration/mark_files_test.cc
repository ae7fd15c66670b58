// The mark job with the files users have and the scans that expose themselves: a short
// pointer line over a bright part (auto exposure), text and a DXF with entities insitu does
// not draw (counted, never silent), sized by placement.size_mm.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

std::string Src(const std::string& rel) { return std::string(INSITU_SOURCE_DIR) + "/" + rel; }

// The arc under 24 mm pointer lines: each is swept four times as often per exposure as the
// shipped 100 mm line, so the stripe is ~4x brighter.
std::string ShortLineJob(const fs::path& dir, const std::string& camera,
                         const std::string& pattern) {
  const fs::path p = dir / "job.yaml";
  std::ofstream(p) << "job: mark\n"
                      "machine:\n  backend: sim\n  calibration: " + Src("calib/as_designed.yaml") +
                          "\nworld: " + Src("config/worlds/default.yaml") +
                          "\nworld_changes:\n  part:\n    kind: arc\n    position_mm: [1.0, -2.0]\n"
                          "scan:\n  x_start_mm: -5.0\n  x_end_mm: 5.0\n  line_spacing_mm: 0.5\n"
                          "  y_start_mm: -12.0\n  y_end_mm: 12.0\n" +
                          camera + "reconstruction:\n  method: 1\n" + pattern;
  return p.string();
}

Result<job::Report> RunJobAt(const std::string& job, const fs::path& out) {
  auto loaded = job::LoadJobFile(job, {});
  if (!loaded.ok()) return loaded.status();
  job::RunOptions options;
  options.out_dir = out.string();
  return job::RunJob(*loaded, options);
}

const char kQr[] =
    "pattern:\n  kind: qr\n  data: \"insitu arc 0001\"\n  module_mm: 0.3\n"
    "placement:\n  offset_mm: [1.0, -2.0]\nhatch:\n  spacing_mm: 0.1\n";

// At the default settings (no camera.exposure_ms: auto exposure) the short line scans fully:
// the stripe is found in the columns the lines cover (all but the arc's steep flanks and the
// speckle's darkest grains: over 80 %), and under 1 % of the lit ones saturate (the target
// puts the brightest 2 % at 55 % of full scale). With the old fixed 50 ms the stripe
// saturates and the job fails saying so, not downstream.
TEST(MarkFiles, AShortLineOnABrightPartScansFullyAtDefaultSettings) {
  const fs::path dir = fs::temp_directory_path() / "insitu_mark_files_short";
  fs::remove_all(dir);
  fs::create_directories(dir);
  auto report = RunJobAt(ShortLineJob(dir, "", kQr), dir / "auto");
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  auto& m = report->metrics;
  ASSERT_TRUE(m.count("columns_expected"));
  EXPECT_GT(m["auto_exposure_shots"], 0);
  EXPECT_LT(m["exposure_ms"], 50.0);
  EXPECT_GT(m["columns_valid"], 0.8 * m["columns_expected"]);
  EXPECT_LT(m["columns_saturated"], 0.01 * (m["columns_valid"] + m["columns_saturated"]));
  std::printf("auto exposure %.2f ms in %g shots: %g of %g columns, %g saturated\n",
              m["exposure_ms"], m["auto_exposure_shots"], m["columns_valid"],
              m["columns_expected"], m["columns_saturated"]);

  auto fixed = RunJobAt(ShortLineJob(dir, "camera:\n  exposure_ms: 50.0\n", kQr), dir / "fixed");
  ASSERT_FALSE(fixed.ok());
  EXPECT_EQ(fixed.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(fixed.status().message().find("saturates"), std::string::npos)
      << fixed.status().message();
}

// Text in a single-stroke font and a DXF with entities insitu does not draw, in one job:
// what was not drawn is in the report (a metric per kind and a warning), the text counted,
// and size_mm scales the drawing to the width asked for.
TEST(MarkFiles, TextAndSkippedEntitiesAreReported) {
  const fs::path dir = fs::temp_directory_path() / "insitu_mark_files_text";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string items =
      "items:\n"
      "  - pattern:\n      kind: text\n      text: \"SN 0042\"\n      font: hershey:futural\n"
      "      height_mm: 1.5\n      align: center\n"
      "    placement:\n      offset_mm: [1.0, 1.0]\n"
      "    hatch:\n      spacing_mm: 0.1\n"
      "  - pattern:\n      kind: dxf\n      file: " +
      Src("tests/pattern/data/dxf/unsupported_r2000.dxf") +
      "\n    placement:\n      size_mm: [6.0, 0]\n      offset_mm: [-2.0, -4.0]\n"
      "      anchor: centre\n"
      "    hatch:\n      spacing_mm: 0.1\n";
  auto report = RunJobAt(ShortLineJob(dir, "", items), dir / "out");
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_TRUE(report->ok) << report->error;
  auto& m = report->metrics;
  EXPECT_EQ(m["pattern_texts"], 1.0);
  int skipped_kinds = 0;
  for (const auto& [key, value] : m) {
    if (key.rfind("pattern_skipped_", 0) != 0) continue;
    ++skipped_kinds;
    EXPECT_GT(value, 0) << key;
    const std::string kind = key.substr(16);
    bool warned = false;
    for (const std::string& w : report->warnings) warned |= w.find(" " + kind + " ") != std::string::npos;
    EXPECT_TRUE(warned) << kind;
  }
  EXPECT_GT(skipped_kinds, 0);
}

}  // namespace
}  // namespace insitu
