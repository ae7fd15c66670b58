// The whole cell's diagnosis in randomised trials (slow, about an hour on two free cores): after
// the default cell is calibrated and its baseline recorded, each machine change is hidden in the
// world at a random size and sign, ten times, with fresh noise each time, and must be named first
// in at least 9 of 10; the unchanged cell must name nothing in 10 of 10, and a change no effect of
// the library describes (the galvos' bearings worn, the camera's lens decentred, the plate domed)
// must be reported unexplained, with nothing named, in 10 of 10. Each effect's trials cover each of
// its parameters (the camera's six axes, both mirrors), the off-library ones several kinds.
//
// Sizes: the gauge's binned heights scatter by ~13 um about the baseline. Each range is chosen
// from single runs (tests/integration/diagnose_machine_test.cc) so that the change moves the
// heights by about 3 to 10 times that, rms: a few times the noise to many times; a change along
// the lines (the Y mirror, the camera moved along y) moves the spots and the gauge's ends by
// as much instead.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

std::string Num(double v) {
  char b[48];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

class DiagnoseMachineTrials : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    testing::KeepTheWorld();
    dir_ = fs::temp_directory_path() / "insitu_diagnose_machine_trials";
    fs::remove_all(dir_);
    auto calibrated = testing::CalibrateWithDiagnoseBaseline(dir_.string());
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
    cal_ = *calibrated;
  }
  struct Verdict {
    std::vector<std::string> cause;
    bool unexplained = false;
  };
  static Verdict Diagnose(std::vector<std::string> sets) {
    sets.push_back("machine.calibration=" + cal_);
    auto r = testing::RunShippedJob("diagnose_machine.yaml", sets, (dir_ / "trial").string());
    if (!r.ok()) return {{"<failed: " + r.status().ToString() + ">"}, false};
    return {nlohmann::json::parse(r->extra_json.at("cause")).get<std::vector<std::string>>(),
            r->extra_json.at("unexplained") == "true"};
  }
  static std::vector<std::string> Causes(std::vector<std::string> sets) {
    return Diagnose(std::move(sets)).cause;
  }
  static fs::path dir_;
  static std::string cal_;
};
fs::path DiagnoseMachineTrials::dir_;
std::string DiagnoseMachineTrials::cal_;

struct Hidden {
  std::string effect;
  // The world change for trial t (0..9), drawn from the generator.
  std::function<std::vector<std::string>(std::mt19937&, int)> change;
};

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}
double Sign(std::mt19937& rng) { return Uniform(rng, 0, 1) < 0.5 ? -1.0 : 1.0; }

TEST_F(DiagnoseMachineTrials, EachHiddenChangeIsNamedFirstIn9Of10) {
  const std::vector<Hidden> hidden = {
      // The camera bumped, about or along one of its six axes in turn (trial t: axis t % 6),
      // each by a size that moves the heights or the gauge's ends by a few times their noise:
      // its aim 0.15-0.6 mm at the plate (0.4-1.7 mrad) panned or tilted, its roll 0.03-0.12 deg
      // about the optical axis, or the whole camera moved 0.1-0.4 mm along x, y or z (aim and
      // position together).
      {"camera_pose",
       [](std::mt19937& rng, int trial) {
         const int axis = trial % 6;
         const double t = Sign(rng) * Uniform(rng, 0.1, 0.4);
         const double aim = Sign(rng) * Uniform(rng, 0.15, 0.6);
         switch (axis) {
           case 0:  // panned: about the camera's vertical axis, its aim along y
             return std::vector<std::string>{"world.camera.look_at_mm=[0.6," + Num(-0.4 + aim) +
                                             ",0.0]"};
           case 1:  // tilted: about its horizontal axis, its aim along x
             return std::vector<std::string>{"world.camera.look_at_mm=[" + Num(0.6 + aim) +
                                             ",-0.4,0.0]"};
           case 2:  // rolled about the optical axis
             return std::vector<std::string>{"world.camera.roll_deg=" +
                                             Num(0.3 + Sign(rng) * Uniform(rng, 0.03, 0.12))};
           default: {
             // Moved along x, y or z: the default cell's mount, position (-182, 1.5, 299)
             // aimed at (0.6, -0.4, 0), shifted whole.
             Eigen::Vector3d d = Eigen::Vector3d::Zero();
             d[axis - 3] = t;
             return std::vector<std::string>{
                 "world.camera.position_mm=[" + Num(-182.0 + d.x()) + "," + Num(1.5 + d.y()) +
                     "," + Num(299.0 + d.z()) + "]",
                 "world.camera.look_at_mm=[" + Num(0.6 + d.x()) + "," + Num(-0.4 + d.y()) + "," +
                     Num(d.z()) + "]"};
           }
         }
       }},
      // Another camera lens: k1 0.3-0.9 off the calibrated -0.06. The gauge fills a small,
      // central part of the image, so only a strong change moves its heights by a few times
      // the noise (sized by the noise, like the pupil's and the stage's below).
      {"camera_distortion",
       [](std::mt19937& rng, int) {
         return std::vector<std::string>{"world.camera.k1=" +
                                         Num(-0.06 + Sign(rng) * Uniform(rng, 0.3, 0.9))};
       }},
      // Another objective: focal length 1.1-3.6 mm off (0.4-1.4 %).
      {"head_scale",
       [](std::mt19937& rng, int) {
         return std::vector<std::string>{"world.scan_head.optics.focal_length_mm=" +
                                         Num(255.0 + Sign(rng) * Uniform(rng, 1.1, 3.6))};
       }},
      // A mirror's zero off, the X mirror's and the Y mirror's in turn. The X mirror moves the
      // lines' planes: 0.07-0.25 mrad (18-64 um) moves the heights by 3-10 times their noise.
      // The Y mirror moves the lines along themselves, which only the pointer's spots on the
      // plate show; each spot scatters by ~25 um (the pointer's speckle on the plate): 0.12-0.4
      // mrad (31-102 um) is 1.2-4 times that, as the X mirror's range is of the heights' noise
      // through their triangulation.
      {"galvo_offset",
       [](std::mt19937& rng, int trial) {
         const bool x = trial % 2 == 0;
         return std::vector<std::string>{
             std::string("world.scan_head.") + (x ? "x" : "y") + "_zero_offset_mrad=" +
             Num(Sign(rng) * (x ? Uniform(rng, 0.07, 0.25) : Uniform(rng, 0.12, 0.4)))};
       }},
      // The exit pupil 45-150 mm higher or lower.
      {"light_plane",
       [](std::mt19937& rng, int) {
         return std::vector<std::string>{"world.scan_head.optics.exit_pupil_height_mm=" +
                                         Num(310.0 + Sign(rng) * Uniform(rng, 45.0, 150.0))};
       }},
      // The focus shifter's scale 0.8-3 per mille per mm off (the field grows by ~3.2 per mille
      // per mm of focus shift from the exit pupil's geometry alone: a quarter of that to all
      // of it wrong).
      {"focus_scale",
       [](std::mt19937& rng, int) {
         return std::vector<std::string>{
             "world.scan_head.field_effects=[{name: focus_scale, "
             "params: [" +
             Num(Sign(rng) * Uniform(rng, 0.8e-3, 3.0e-3)) + "]}]"};
       }},
      // The stage's screw 1.5-5 % off.
      {"stage_scale",
       [](std::mt19937& rng, int) {
         return std::vector<std::string>{"world.stage.scale_error_ppm=" +
                                         Num(Sign(rng) * Uniform(rng, 15000.0, 50000.0))};
       }},
  };
  std::mt19937 rng(2026);
  int seed = 100;
  for (const Hidden& h : hidden) {
    int first = 0;
    std::string misses;
    for (int t = 0; t < 10; ++t) {
      std::vector<std::string> sets = h.change(rng, t);
      sets.push_back("world.seed=" + std::to_string(seed++));
      const std::vector<std::string> causes = Causes(sets);
      if (!causes.empty() && causes.front() == h.effect) {
        ++first;
      } else {
        misses +=
            " [" + sets.front() + " -> " + (causes.empty() ? "nothing" : causes.front()) + "]";
      }
    }
    std::printf("%s named first in %d of 10%s\n", h.effect.c_str(), first, misses.c_str());
    EXPECT_GE(first, 9) << h.effect << misses;
  }
}

TEST_F(DiagnoseMachineTrials, TheUnchangedCellNamesNothingIn10Of10) {
  int clean = 0;
  for (int t = 0; t < 10; ++t) {
    const Verdict v = Diagnose({"world.seed=" + std::to_string(200 + t)});
    if (v.cause.empty() && !v.unexplained) ++clean;
  }
  std::printf("unchanged: nothing named, nothing unexplained in %d of 10\n", clean);
  EXPECT_EQ(clean, 10);
}

// Changes no effect of the library describes, each kind in turn (trial t: kind t % 4), each
// moving the heights or the spots by 1 to 10 times their noise:
//  - worn bearings: where the mirrors settle after each jump scatters by 100-300 urad rms (an
//    intelliSCAN-class head quotes < 2), so each scan line lies its own 30-90 um off;
//  - the camera's lens decentred along its x (p1) or its y (p2) by 0.004-0.012: a
//    prism-like distortion, which no pose and no radial term reproduces;
//  - the stage's plate domed by 1-2.5 mm over its 400 mm: the gauge balances on the crown
//    (its heights as before) while the plate under the spots falls by 16-200 um, more with
//    their distance from the centre (the spots' column structure: ~20-50 um beside ~19 um of
//    speckle). A dish is not drawn: the gauge would rest on its corners, lifted as a whole,
//    and through a side camera a lifted surface is a moved camera or mirror zero exactly (the
//    stripe and the spots shift alike), so the diagnosis names that beside the curvature it
//    leaves unexplained (docs/model.md).
TEST_F(DiagnoseMachineTrials, AChangeOutsideTheLibraryIsUnexplainedIn10Of10) {
  std::mt19937 rng(7);
  int unexplained = 0;
  std::string misses;
  for (int t = 0; t < 10; ++t) {
    std::string change;
    switch (t % 4) {
      case 0:
        change = "world.scan_head.repeatability_urad=" + Num(Uniform(rng, 100.0, 300.0));
        break;
      case 1:
        change = "world.camera.p1=" + Num(0.0002 + Sign(rng) * Uniform(rng, 0.004, 0.012));
        break;
      case 2:
        change = "world.camera.p2=" + Num(-0.0001 + Sign(rng) * Uniform(rng, 0.004, 0.012));
        break;
      default:
        change = "world.stage.plate_bow_mm=" + Num(Uniform(rng, 1.0, 2.5));
        break;
    }
    const Verdict v = Diagnose({change, "world.seed=" + std::to_string(300 + t)});
    if (v.unexplained && v.cause.empty()) {
      ++unexplained;
    } else {
      misses += " [" + change + " -> " + (v.cause.empty() ? "" : v.cause.front()) +
                (v.unexplained ? " unexplained" : " explained") + "]";
    }
  }
  std::printf("off-library: unexplained, nothing named in %d of 10%s\n", unexplained,
              misses.c_str());
  EXPECT_EQ(unexplained, 10) << misses;
}

}  // namespace
}  // namespace insitu
