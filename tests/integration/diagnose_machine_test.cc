// The whole cell diagnosed (job diagnose_machine, CONTRACT.md "Machine diagnosis"): the default
// cell is calibrated, a baseline of the machine as calibrated is recorded, and the machine is
// changed in the simulator's world the way a cell changes in use: the camera bumped, its lens
// swapped, the objective swapped for one of another focal length, the mirrors' zero drifting,
// the pointer's light planes leaning otherwise (the exit pupil), the stage's travel off, the
// focus shifter's travel off, the galvos' bearings worn. Each change of the library must be named
// first, the worn bearings (outside it) reported unexplained with nothing named; the unchanged
// machine (a fresh noise realisation) must be named nothing.
//
// Sizes: the heights of 2 mm bins scatter by ~13 um about the baseline (speckle, both scans).
// Each change is set to move the gauge's heights by several times that.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

using testing::With;

class DiagnoseMachine : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    testing::KeepTheWorld();
    dir_ = fs::temp_directory_path() / "insitu_diagnose_machine";
    fs::remove_all(dir_);
    auto calibrated = testing::CalibrateWithDiagnoseBaseline(dir_.string());
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
    cal_ = *calibrated;
    ASSERT_TRUE(fs::exists(dir_ / "diagnose_baseline.csv"));
  }

  // The causes named after the world changes `sets` (and a fresh noise seed); `effects`, when
  // given, receives the report's effects.
  static std::vector<std::string> Causes(const std::string& name, std::vector<std::string> sets,
                                         nlohmann::json* effects = nullptr) {
    sets.push_back("machine.calibration=" + cal_);
    auto r = testing::RunShippedJob("diagnose_machine.yaml", sets, (dir_ / name).string());
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (!r.ok()) return {"<failed>"};
    if (effects != nullptr) *effects = nlohmann::json::parse(r->extra_json.at("effects"));
    const auto cause = nlohmann::json::parse(r->extra_json.at("cause"));
    std::printf("%s: cause %s, held out %.1f -> %.1f um\n", name.c_str(), cause.dump().c_str(),
                1e3 * r->metrics["nominal_cv_rms_mm"], 1e3 * r->metrics["extended_cv_rms_mm"]);
    EXPECT_TRUE(fs::exists(dir_ / name / "residuals.png"));
    return cause.get<std::vector<std::string>>();
  }

  static fs::path dir_;
  static std::string cal_;
};
fs::path DiagnoseMachine::dir_;
std::string DiagnoseMachine::cal_;

TEST_F(DiagnoseMachine, AnUnchangedMachineNamesNothing) {
  EXPECT_TRUE(Causes("null", {"world.seed=2"}).empty());
  const auto report =
      nlohmann::json::parse(std::ifstream((dir_ / "null" / "report.json").string()));
  EXPECT_FALSE(report.at("unexplained").get<bool>());
}

TEST_F(DiagnoseMachine, EachChangeIsNamedFirst) {
  struct Case {
    std::string name, effect;
    std::vector<std::string> sets;
  };
  const std::vector<Case> cases = {
      // The camera turned ~1 mrad (its aim moved 0.3 mm at 350 mm).
      {"bumped", "camera_pose", {"world.camera.look_at_mm=[0.6,-0.1,0.0]"}},
      // Another camera lens: pincushion k1 +0.10 where the calibrated one had barrel -0.06.
      {"lens", "camera_distortion", {"world.camera.k1=0.1"}},
      // An objective 0.16 % shorter: the field 0.1 mm smaller at its edge.
      {"objective", "head_scale", {"world.scan_head.optics.focal_length_mm=254.6"}},
      // The X mirror's zero 0.2 mrad off: every line 51 um over.
      {"zero", "galvo_offset", {"world.scan_head.x_zero_offset_mrad=0.2"}},
      // The Y mirror's zero -0.25 mrad off: every line 64 um along itself, which no height
      // shows; the pointer's spots on the plate do.
      {"zero_y", "galvo_offset", {"world.scan_head.y_zero_offset_mrad=-0.25"}},
      // The whole camera moved 0.2 mm along y, along the lines (aim and position together):
      // the spots move as they do for the Y mirror, but the gauge's ends move with them.
      {"shifted",
       "camera_pose",
       {"world.camera.position_mm=[-182.0,1.7,299.0]", "world.camera.look_at_mm=[0.6,-0.2,0.0]"}},
      // The exit pupil 20 mm higher: the planes lean 0.1 mrad less per 10 mm of field.
      {"pupil", "light_plane", {"world.scan_head.optics.exit_pupil_height_mm=330"}},
      // The stage's screw 0.8 % long: the second pass 32 um lower than commanded.
      {"stage", "stage_scale", {"world.stage.scale_error_ppm=8000"}},
      // The focus shifter's travel off: the field 0.1 % larger per mm of focus shift (at the
      // second pass's -4 mm, lines 56 um further out at the gauge's edge).
      {"focus",
       "focus_scale",
       {"world.scan_head.field_effects=[{name: focus_scale, params: [0.001]}]"}},
  };
  int seed = 20;
  for (const Case& c : cases) {
    nlohmann::json effects;
    const std::vector<std::string> causes =
        Causes(c.name, With(c.sets, {"world.seed=" + std::to_string(seed++)}), &effects);
    ASSERT_FALSE(causes.empty()) << c.name;
    EXPECT_EQ(causes.front(), c.effect) << c.name;
    if (c.effect == "light_plane") {
      // The sign and size of what changed: the pupil 20 mm higher. The model leans the planes
      // to first order in x / L and leaves out the pupil's aberration (3 % at 0.2 rad), so
      // within a factor of 2, not within its standard error.
      const double pupil = effects[0]["params"]["pupil_mm"].get<double>();
      EXPECT_GT(pupil, 10.0);
      EXPECT_LT(pupil, 40.0);
    }
    if (c.name == "zero_y") {
      // -0.25 mrad x f 255 mm = -63.8 um along y; the spots scatter by a few um and the
      // field's pincushion changes the shift by under 1 % over their +-40 mm: 5 um.
      EXPECT_NEAR(effects[0]["params"]["oy_mm"].get<double>(), -0.0638, 0.005);
      EXPECT_NEAR(effects[0]["params"]["ox_mm"].get<double>(), 0.0, 0.005);
    }
    if (c.effect == "focus_scale") {
      // c = 1e-3 /mm exactly in the world; the model's form is the world's: 3 standard errors.
      const double v = effects[0]["params"]["c_permille_per_mm"].get<double>();
      const double se = effects[0]["stderr"]["c_permille_per_mm"].get<double>();
      EXPECT_NEAR(v, 1.0, 3.0 * se);
    }
    if (c.effect == "stage_scale") {
      // 8 per mille; the stage's travel is exactly linear in the simulator: 3 standard errors.
      const double s = effects[0]["params"]["s_permille"].get<double>();
      const double se = effects[0]["stderr"]["s_permille"].get<double>();
      EXPECT_NEAR(s, 8.0, 3.0 * se);
    }
  }
}

// The galvos' bearings worn: every line settles its own ~40 um off (150 urad rms). No effect of
// the library moves lines independently: the structure is reported, and nothing is named.
TEST_F(DiagnoseMachine, AChangeOutsideTheLibraryIsUnexplainedAndNothingIsNamed) {
  auto r = testing::RunShippedJob(
      "diagnose_machine.yaml",
      {"world.scan_head.repeatability_urad=150", "world.seed=31", "machine.calibration=" + cal_},
      (dir_ / "worn").string());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->extra_json.at("unexplained"), "true");
  EXPECT_EQ(r->extra_json.at("cause"), "[]");
  // The structure left is the change's, several times the bins' ~13 um scatter.
  EXPECT_GT(r->metrics.at("residual_structure_mm"), 2.0 * r->metrics.at("residual_noise_mm"));
}

// Two changes at once, one in the library and one not: the camera bumped and the bearings worn
// (60 urad). camera_pose takes most of the structure away and is named; what the bearings leave
// is flagged beside it.
TEST_F(DiagnoseMachine, ACauseBesideAChangeOutsideTheLibraryIsStillNamed) {
  auto r = testing::RunShippedJob(
      "diagnose_machine.yaml",
      {"world.camera.look_at_mm=[0.6,-0.1,0.0]", "world.scan_head.repeatability_urad=60",
       "world.seed=61", "machine.calibration=" + cal_},
      (dir_ / "bumped_and_worn").string());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->extra_json.at("cause"), "[\"camera_pose\"]");
  EXPECT_EQ(r->extra_json.at("unexplained"), "true");
}

// The camera lens decentred (p1 0.0002 -> 0.01): camera_pose fits part of it (the image's shift)
// but leaves more than a quarter of its structure's variance: it is reported as partial, and
// nothing is named.
TEST_F(DiagnoseMachine, APartialFitIsNotACause) {
  auto r = testing::RunShippedJob(
      "diagnose_machine.yaml",
      {"world.camera.p1=0.01", "world.seed=62", "machine.calibration=" + cal_},
      (dir_ / "decentred").string());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->extra_json.at("cause"), "[]");
  EXPECT_EQ(r->extra_json.at("effects"), "[]");
  EXPECT_EQ(r->extra_json.at("unexplained"), "true");
  ASSERT_TRUE(r->extra_json.count("partial"));
  const auto partial = nlohmann::json::parse(r->extra_json.at("partial"));
  ASSERT_FALSE(partial.empty());
  EXPECT_EQ(partial[0]["name"], "camera_pose");
  EXPECT_EQ(r->metrics.at("gain"), 1.0);
  EXPECT_EQ(r->metrics.at("extended_cv_rms_mm"), r->metrics.at("nominal_cv_rms_mm"));
}

// The stage's plate domed by 2 mm over its 400 mm: the gauge balances on the crown, its heights
// as before, while the plate under the pointer's spots falls by 30-160 um, the more the farther
// from the centre. Only the spots show it, smoothly along their columns: unexplained, nothing
// named (a pose or a mirror zero would move the gauge's heights as well).
TEST_F(DiagnoseMachine, ADomedPlateShowsInTheSpotsAndIsUnexplained) {
  auto r = testing::RunShippedJob(
      "diagnose_machine.yaml",
      {"world.stage.plate_bow_mm=2", "world.seed=33", "machine.calibration=" + cal_},
      (dir_ / "domed").string());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->extra_json.at("cause"), "[]");
  EXPECT_EQ(r->extra_json.at("unexplained"), "true");
  // The spots' structure (~40 um, twice their ~19 um of speckle); the heights' below half of
  // their ~13 um of noise.
  EXPECT_GT(r->metrics.at("residual_spot_structure_mm"), r->metrics.at("residual_spot_noise_mm"));
  EXPECT_LT(r->metrics.at("residual_structure_mm"), 0.5 * r->metrics.at("residual_noise_mm"));
}

// A baseline recorded with the passes focused otherwise holds the calibration's residuals at
// another focus: refused, with what to do.
TEST_F(DiagnoseMachine, ABaselineFocusedOtherwiseIsRefused) {
  const std::string other = (dir_ / "unfocused_baseline.csv").string();
  ASSERT_TRUE(
      testing::RunShippedJob("diagnose_machine.yaml",
                             {"machine.calibration=" + cal_, "diagnosis.refocus=false",
                              "diagnosis.record_baseline=true", "diagnosis.baseline=" + other},
                             (dir_ / "unfocused").string())
          .ok());
  auto r = testing::RunShippedJob("diagnose_machine.yaml",
                                  {"machine.calibration=" + cal_, "diagnosis.baseline=" + other},
                                  (dir_ / "mismatch").string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("record the baseline again"), std::string::npos)
      << r.status().message();
}

TEST_F(DiagnoseMachine, WithoutABaselineItSaysWhatToDo) {
  auto r = testing::RunShippedJob(
      "diagnose_machine.yaml",
      {"machine.calibration=" + cal_, "diagnosis.baseline=" + (dir_ / "none.csv").string()},
      (dir_ / "no_baseline").string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("record_baseline"), std::string::npos)
      << r.status().message();
}

}  // namespace
}  // namespace insitu
