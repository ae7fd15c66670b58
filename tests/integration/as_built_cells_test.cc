// Lengths and heights on any as-built cell (slow: about three and a half minutes a cell on two
// cores). Each cell is drawn within catalogue tolerances, none of them named by another test:
// the head (objective focal length +-0.5 %, mirror spacing +-1 mm, the lens's own f-theta
// deviation, axis tilts, mirror zero errors, the pilot beam's alignment and lateral colour)
// and the side camera (lens focal length +-2 %, radial distortion, mounting +-10 mm and
// +-1.5 deg in aim and roll), the room light (100-1000 lux) and the part's albedo (0.2-0.6).
// On each an operator runs calibrate, field_calibration and the step-gauge accuracy job; each
// must measure the 80 mm gauge within +-0.05 mm and its binned heights within +-0.05 mm.
//
// The algorithms see none of the draw: only the frames, the commands and the calibration
// files the jobs write. INSITU_AS_BUILT_CELLS=N runs N cells (default 6); the draws come from
// a fixed seed, so a failure names a cell that can be run again.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

using testing::With;

std::string Key(const std::string& key, double value) {
  char text[160];
  std::snprintf(text, sizeof text, "%s=%.6g", key.c_str(), value);
  return text;
}

std::string Triple(const std::string& key, double x, double y, double z) {
  char text[200];
  std::snprintf(text, sizeof text, "%s=[%.4f,%.4f,%.4f]", key.c_str(), x, y, z);
  return text;
}

// One cell's world keys, drawn uniformly within the tolerances above. The head's controller
// corrects for the data sheet (scan_head.design of config/worlds/as_built.yaml: f 255 mm,
// mirrors 16 mm apart); the camera's drawing is the default cell's mount.
std::vector<std::string> DrawCell(std::mt19937& rng, int index) {
  auto u = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  const std::string h = "world.scan_head.";
  const std::string c = "world.camera.";
  std::vector<std::string> w = {"world=../worlds/as_built.yaml"};
  w.push_back(Key(h + "optics.focal_length_mm", 255.0 * (1.0 + u(-0.005, 0.005))));
  w.push_back(Key(h + "optics.mirror_separation_mm", 16.0 + u(-1.0, 1.0)));
  w.push_back(Key(h + "optics.ftheta_c3", u(-0.05, 0.05)));
  w.push_back(Key(h + "optics.x_axis_tilt_mrad", u(-1.5, 1.5)));
  w.push_back(Key(h + "optics.y_axis_tilt_mrad", u(-1.5, 1.5)));
  w.push_back(Key(h + "x_zero_offset_mrad", u(-0.4, 0.4)));
  w.push_back(Key(h + "y_zero_offset_mrad", u(-0.4, 0.4)));
  w.push_back(Key(h + "pointer.offset_x_mrad", u(-0.15, 0.15)));
  w.push_back(Key(h + "pointer.offset_y_mrad", u(-0.15, 0.15)));
  w.push_back(Key(h + "pointer.lateral_colour_pct", u(-0.6, 0.6)));
  w.push_back(Key(c + "lens_focal_length_mm", 15.0 * (1.0 + u(-0.02, 0.02))));
  w.push_back(Key(c + "k1", u(-0.14, -0.02)));
  w.push_back(Key(c + "k2", u(0.0, 0.16)));
  // The drawing's mount (-180, 0, 300) aimed at the origin, off by up to 10 mm in each axis,
  // up to 1.5 deg in aim (~9 mm at the 350 mm to the plate) and in roll.
  w.push_back(Triple(c + "position_mm", -180.0 + u(-10, 10), u(-10, 10), 300.0 + u(-10, 10)));
  w.push_back(Triple(c + "look_at_mm", u(-9, 9), u(-9, 9), 0.0));
  w.push_back(Key(c + "roll_deg", u(-1.5, 1.5)));
  w.push_back(Key("world.light.ambient_lux", u(100.0, 1000.0)));
  w.push_back(Key("world.part.albedo", u(0.2, 0.6)));
  w.push_back("world.seed=" + std::to_string(1000 + index));
  return w;
}

TEST(AsBuiltCells, EveryDrawnCellMeasuresTheGaugeWithinTheBar) {
  testing::KeepTheWorld();
  int cells = 6;
  if (const char* n = std::getenv("INSITU_AS_BUILT_CELLS")) cells = std::max(1, std::atoi(n));
  std::mt19937 rng(20261128);
  for (int i = 0; i < cells; ++i) {
    const std::vector<std::string> world = DrawCell(rng, i);
    std::string drawn;
    for (const std::string& k : world) drawn += " --set " + k;
    SCOPED_TRACE("cell " + std::to_string(i) + ":" + drawn);
    std::printf("cell %d:%s\n", i, drawn.c_str());
    const fs::path dir = fs::temp_directory_path() / ("insitu_as_built_cell_" + std::to_string(i));
    fs::remove_all(dir);
    std::string measured;
    auto field = testing::CalibrateAndMeasureHead(dir.string(), world, &measured);
    ASSERT_TRUE(field.ok()) << field.status().ToString();
    auto gauge = testing::RunShippedJob(
        "accuracy_step_gauge.yaml",
        With(world, {"scan.line_spacing_mm=1.0", "machine.calibration=" + measured}),
        (dir / "accuracy").string());
    ASSERT_TRUE(gauge.ok()) << gauge.status().ToString();
    auto& m = gauge->metrics;
    std::printf("cell %d: field %.2f um rms after (%.2f %% removed); length error %+.4f mm "
                "(std %.3f, %g lines), binned heights %.4f mm\n",
                i, field->metrics["field_error_rms_um_after"],
                field->metrics["distortion_removed_pct"], m["length_error_mm"],
                m["length_std_mm"], m["length_lines"], m["height_error_max_abs_binned_mm"]);
    std::fflush(stdout);
    // The bar: +-0.05 mm on the 80 mm gauge's length and on every 1 mm bin's mean
    // height (a pixel on the plate is ~0.08 mm; a line's ends scatter by ~0.05 mm, averaged
    // over ~50 lines).
    EXPECT_LE(std::abs(m["length_error_mm"]), 0.05);
    EXPECT_LE(m["height_error_max_abs_binned_mm"], 0.05);
  }
}

}  // namespace
}  // namespace insitu
