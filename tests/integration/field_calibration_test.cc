// The machine measures its own scan head (issue "camera field calibration, closed loop"): on a
// head built differently from its design (focal length +0.47 %, mirror spacing +0.9 mm, lens
// distortion, a tilted mirror axis, mirror zero errors, a pointer misaligned against the
// marking beam with lateral colour) and a camera mounted elsewhere than drawn, an operator runs
// calibrate, then field_calibration, then the step-gauge accuracy job. The field calibration
// must remove the field error it measures, its correction must put the marking beam where it
// is asked in the simulator's truth, and the step gauge must then measure its length.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>

#include "insitu/calib/calibration.h"
#include "insitu/hw/cell.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/hw/machine.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/job/cor_reading.h"
#include "insitu/optics/scan_head.h"
#include "insitu/sim/world.h"
#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

using testing::KeepTheWorld;

// config/worlds/as_built.yaml: f 256.2 mm for 255, mirrors 16.9 mm apart for 16, c3 0.04, the
// X axis tilted 1 mrad, zero errors 0.3 / -0.2 mrad, the pointer 0.1 / -0.05 mrad off with
// -0.3 % lateral colour, the camera 6 mm from its drawing.
const std::vector<std::string> kAsBuilt = {"world=../worlds/as_built.yaml"};

using testing::With;

std::string Slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// rms distance (um) between where points landed and where they were asked, after the best
// rigid fit (the machine's galvo frame may sit a rigid motion away from the world's).
double RigidRmsUm(const std::vector<Eigen::Vector2d>& asked,
                  const std::vector<Eigen::Vector2d>& landed) {
  Eigen::MatrixXd a(2, asked.size()), l(2, landed.size());
  for (size_t i = 0; i < asked.size(); ++i) {
    a.col(i) = asked[i];
    l.col(i) = landed[i];
  }
  const Eigen::MatrixXd rigid = Eigen::umeyama(a, l, false);
  double ss = 0;
  for (size_t i = 0; i < asked.size(); ++i) {
    ss += (rigid.topLeftCorner(2, 2) * asked[i] + rigid.topRightCorner(2, 1) - landed[i])
              .squaredNorm();
  }
  return std::sqrt(ss / asked.size()) * 1e3;
}

TEST(FieldCalibrationJob, AsBuiltHeadIsMeasuredCorrectedAndUsed) {
  KeepTheWorld();
  const fs::path dir = fs::temp_directory_path() / "insitu_field_calibration_test";
  fs::remove_all(dir);
  const std::string cal = (dir / "machine.yaml").string();
  const std::string measured = (dir / "measured.yaml").string();
  {
    auto calibrated = testing::QuickCalibrate(cal, (dir / "calibrate").string(), kAsBuilt);
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  }
  const std::vector<std::string> gauge = {"scan.line_spacing_mm=1.0"};
  auto before = testing::RunShippedJob(
      "accuracy_step_gauge.yaml", With(With(kAsBuilt, gauge), {"machine.calibration=" + cal}),
      (dir / "accuracy_before").string());
  ASSERT_TRUE(before.ok()) << before.status().ToString();
  // The head's 0.47 % scale, absorbed silently by the camera's pose: the gauge comes out short
  // by several times the 0.05 mm bar.
  EXPECT_LT(before->metrics["length_error_mm"], -0.15);

  auto field = testing::RunShippedJob(
      "field_calibration.yaml",
      With(kAsBuilt, {"machine.calibration=" + cal, "output.calibration=" + measured}),
      (dir / "field").string());
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  auto& m = field->metrics;
  std::printf("field: %.1f um rms before, %.2f um after (%.2f %% removed); physics %.2f, "
              "bilinear 11 %.2f, quadrant %.1f um\n",
              m["field_error_rms_um_before"], m["field_error_rms_um_after"],
              m["distortion_removed_pct"], m["model_physics_rms_um"], m["model_bilinear_11_rms_um"],
              m["model_quadrant_rms_um"]);
  EXPECT_EQ(m["targets_found"], m["targets_expected"]);
  EXPECT_EQ(m["check_points"], 100.0);
  EXPECT_GT(m["field_error_rms_um_before"], 100.0);  // 0.47 % over a +-60 mm field
  // The bars of the issue: >= 99 % removed, <= 10 um rms after, measured at check points the
  // fit never saw. The side camera's centres scatter by ~1.3 um per target (the circle fitted
  // to ~150 edge points of a 30 px disc, 94 um pixels): the after error sits near 2 um.
  EXPECT_GE(m["distortion_removed_pct"], 99.0);
  EXPECT_LE(m["field_error_rms_um_after"], 10.0);
  // Physics first: the head model leaves less than the densest table at the check points.
  EXPECT_LT(m["model_physics_rms_um"], m["model_bilinear_11_rms_um"]);
  EXPECT_LT(m["model_physics_table_rms_um"], m["model_quadrant_rms_um"]);
  for (const char* a : {"field.csv", "field_before.png", "field_after.png", "correction.csv",
                        "field.cor", "calibration.yaml"}) {
    EXPECT_TRUE(fs::exists(dir / "field" / a)) << a;
  }

  // The simulator's truth: where the corrected commands really put the marking beam. The
  // galvo frame the machine now works in is the measured head's: it may sit a rigid motion
  // away from the world's (the mirrors' zero errors move the whole field; the board lay
  // anywhere), so positions are compared after the best rigid fit. 10 um rms: the bar.
  auto set = calib::LoadCalibration(measured);
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_TRUE(set->head.measured);
  ASSERT_TRUE(testing::LastSimWorld());
  // A copy: later jobs replace the world the test keeps.
  const sim::ScanHeadOptions sh = testing::LastSimWorld()->options().scan_head;
  optics::HeadModel truth;
  truth.design = sh.design;
  truth.built = sh.optics;
  truth.x_zero_offset_mrad = sh.x_zero_offset_mrad;
  truth.y_zero_offset_mrad = sh.y_zero_offset_mrad;
  // rms distance (um) between where the saved calibration's corrected commands put the marking
  // beam and where they were asked, after the best rigid fit.
  const auto truth_rms = [&](const calib::CalibrationSet& c) {
    std::vector<Eigen::Vector2d> asked, landed;
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-60.0, 60.0);
    for (int i = 0; i < 200; ++i) {
      const Eigen::Vector3d p(u(rng), u(rng), 0.0);
      Eigen::Vector3d cmd, spot;
      EXPECT_TRUE(c.head.MarkCommandFor(p, &cmd));
      EXPECT_TRUE(truth.Spot(cmd, sh.marking.Path(), &spot));
      asked.push_back(p.head<2>());
      landed.push_back(spot.head<2>());
    }
    return RigidRmsUm(asked, landed);
  };
  const double truth_rms_um = truth_rms(*set);
  std::printf("truth: corrected marks within %.2f um rms of where asked\n", truth_rms_um);
  EXPECT_LE(truth_rms_um, 10.0);
  // field.cor is the whole table a board driving this head needs (the measured correction on
  // the head's design correction): read back, the physics reads it in the documented
  // convention of a board whose first word drives the first mirror, and explains >= 95 % of
  // it (the bar)...
  {
    const std::string cor = (dir / "field" / "field.cor").string();
    auto read = job::ReadCorByPhysics(cor);
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    std::printf("field.cor: %s; %s\n", read->summary.c_str(), read->evidence.c_str());
    EXPECT_FALSE(read->forced);
    EXPECT_EQ(read->readings[read->used], hw::lmc::DocumentedReading(false));
    EXPECT_GE(read->choice.fits[read->used].explained, 0.95);
    // ... and an LMC board given it (the emulator applies the uploaded table as the documented
    // convention says) puts the marking beam of the same as-built head, now driven linearly
    // as an analogue head behind a board is, where the commands ask: within the same 10 um
    // after the best rigid fit as the machine's own correction above. What the table adds to
    // that: its whole units (2.1 um at 140 mm, 0.6 um rms) and bilinear steps of 2.2 mm over a
    // correction whose curvature is ~4e-3 /mm at the edge (~2 um).
    sim::WorldOptions w = testing::LastSimWorld()->options();
    w.scan_head.own_correction = false;
    w.part.kind = "none";
    auto board_world = std::make_shared<sim::SimWorld>(w);
    hw::MachineConfig config;
    config.scanner = "lmc";
    config.lmc.transport = "sim_board";
    config.lmc.correction_file = cor;
    config.lmc.board.lens_mm = 2.0 * sh.field_half_size_mm;
    auto machine = hw::CreateMachineOn(config, board_world);
    ASSERT_TRUE(machine.ok()) << machine.status().ToString();
    std::vector<Eigen::Vector2d> asked, landed;
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-60.0, 60.0);
    for (int i = 0; i < 200; ++i) {
      const Eigen::Vector3d p(u(rng), u(rng), 0.0);
      optics::MirrorAngles a;
      ASSERT_TRUE(board_world->CommandToAngles(p, &a));
      const optics::ChiefRay ray = optics::ScanOptics(sh.optics).Trace(a, sh.marking.Path());
      asked.push_back(p.head<2>());
      landed.push_back(ray.focal_point_in_world.head<2>());
    }
    const double board_um = RigidRmsUm(asked, landed);
    std::printf("field.cor through an LMC board on the linear head: marks within %.2f um rms\n",
                board_um);
    EXPECT_LE(board_um, 10.0);
  }

  // The pointer's path, measured against the marking beam: lateral colour to 0.02 % (the
  // fit's standard error from 121 spots at ~19 um is ~0.003 %; the camera's own scale error
  // adds ~0.005 %).
  EXPECT_NEAR(set->head.pointer.lateral_colour_pct, -0.3, 0.02);
  // The mirror separation from the pointer's chief rays at 0 and 15 mm: its standard error is
  // ~0.16 mm (242 spots at ~20 um; 0.9 mm moves an edge spot 13 um at 15 mm); 3 sigma.
  EXPECT_NEAR(set->head.model.built.mirror_separation_mm, 16.9, 0.5);

  // The non-destructive variant: the pointer's spots on the plate instead of marks. Each spot's
  // centroid scatters by ~19 um on the plate (speckle on a 0.4 mm spot: ~0.2 px), so its
  // correction is good to that: <= 40 um rms after (about twice the scatter: the spot measured
  // after, and the noise the fit passes into the correction), a fifth of the ~175 um the
  // pointer's field shows before (its -0.3 % lateral colour takes back part of the 0.47 %).
  auto spots = testing::RunShippedJob(
      "field_calibration.yaml",
      With(kAsBuilt, {"machine.calibration=" + cal, "output.calibration=" + (dir / "p.yaml").string(),
                      "target.kind=pointer", "grid.n=7"}),
      (dir / "pointer").string());
  ASSERT_TRUE(spots.ok()) << spots.status().ToString();
  // Run again on a machine whose pointer path was measured by the marked targets: the spots
  // are taken to the marking beam through it, so marks no longer carry the pointer's -0.3 %
  // lateral colour (~180 um at 60 mm). What is left is the spots' own scatter passed into the
  // correction: <= 40 um, as above.
  auto respots = testing::RunShippedJob(
      "field_calibration.yaml",
      With(kAsBuilt, {"machine.calibration=" + measured,
                      "output.calibration=" + (dir / "p2.yaml").string(), "target.kind=pointer",
                      "grid.n=7"}),
      (dir / "pointer2").string());
  ASSERT_TRUE(respots.ok()) << respots.status().ToString();
  {
    auto p2 = calib::LoadCalibration((dir / "p2.yaml").string());
    ASSERT_TRUE(p2.ok()) << p2.status().ToString();
    const double marks_um = truth_rms(*p2);
    std::printf("pointer variant after a marked calibration: marks within %.1f um rms\n", marks_um);
    EXPECT_LE(marks_um, 40.0);
  }
  std::printf("pointer variant: %.1f um rms before, %.1f um after\n",
              spots->metrics["field_error_rms_um_before"], spots->metrics["field_error_rms_um_after"]);
  EXPECT_LE(spots->metrics["field_error_rms_um_after"], 40.0);
  EXPECT_LT(spots->metrics["field_error_rms_um_after"],
            0.2 * spots->metrics["field_error_rms_um_before"]);

  // Seed 001's crosses instead of discs, found in the frame resampled onto the plate: their
  // centres rest on the bars' centre lines (~50 cross-sections each, 5 px wide), a little
  // noisier than a disc's ~150 edge points, so the same bars hold (~3 um after).
  auto crosses = testing::RunShippedJob(
      "field_calibration.yaml",
      With(kAsBuilt, {"machine.calibration=" + cal, "output.calibration=" + (dir / "x.yaml").string(),
                      "target.kind=cross", "grid.n=7"}),
      (dir / "cross").string());
  ASSERT_TRUE(crosses.ok()) << crosses.status().ToString();
  std::printf("cross targets: %.1f um rms before, %.2f um after (%.2f %% removed)\n",
              crosses->metrics["field_error_rms_um_before"],
              crosses->metrics["field_error_rms_um_after"],
              crosses->metrics["distortion_removed_pct"]);
  EXPECT_EQ(crosses->metrics["targets_found"], crosses->metrics["targets_expected"]);
  EXPECT_GE(crosses->metrics["distortion_removed_pct"], 99.0);
  EXPECT_LE(crosses->metrics["field_error_rms_um_after"], 10.0);

  // The rest of the machine uses what was measured: the gauge's length and heights hold.
  auto after = testing::RunShippedJob(
      "accuracy_step_gauge.yaml",
      With(With(kAsBuilt, gauge), {"machine.calibration=" + measured}),
      (dir / "accuracy_after").string());
  ASSERT_TRUE(after.ok()) << after.status().ToString();
  std::printf("step gauge: length error %.3f mm before, %.3f mm after; binned height %.3f mm\n",
              before->metrics["length_error_mm"], after->metrics["length_error_mm"],
              after->metrics["height_error_max_abs_binned_mm"]);
  EXPECT_LE(std::abs(after->metrics["length_error_mm"]), 0.05);
  EXPECT_LE(after->metrics["height_error_max_abs_binned_mm"], 0.05);
  EXPECT_LE(after->metrics["height_error_max_abs_binned_mm_method1"], 0.05);
}

// Bad input gets a clear error and the previous calibration stays as it was.
TEST(FieldCalibrationJob, FailuresKeepThePreviousCalibration) {
  KeepTheWorld();
  const fs::path dir = fs::temp_directory_path() / "insitu_field_calibration_bad";
  fs::remove_all(dir);
  fs::create_directories(dir);
  // The as-designed file stands in for a previous calibration: the failures here come before
  // any measurement depends on the camera's intrinsics.
  const std::string cal = (dir / "machine.yaml").string();
  fs::copy_file(std::string(INSITU_SOURCE_DIR) + "/calib/as_designed.yaml", cal);
  const std::string original = Slurp(cal);
  const auto run = [&](const std::vector<std::string>& sets, const std::string& out) {
    return testing::RunShippedJob(
        "field_calibration.yaml",
        With({"machine.calibration=" + cal, "output.calibration=" + cal}, sets),
        (dir / out).string());
  };

  auto beyond = run({"grid.half_size_mm=69.5"}, "beyond");
  ASSERT_FALSE(beyond.ok());
  EXPECT_NE(beyond.status().message().find("beyond the head's field"), std::string::npos)
      << beyond.status().message();

  auto no_board = run({"world.board.present=false"}, "no_board");
  ASSERT_FALSE(no_board.ok());
  EXPECT_NE(no_board.status().message().find("no plate plane"), std::string::npos)
      << no_board.status().message();

  // A laser too weak to ablate the plate: nothing to find, and the job names the targets.
  auto weak = run({"marking.power=0.002", "grid.n=5", "pointer.enabled=false"}, "weak");
  ASSERT_FALSE(weak.ok());
  EXPECT_NE(weak.status().message().find("targets not found: 25 of the 25"), std::string::npos)
      << weak.status().message();
  EXPECT_NE(weak.status().message().find("(-60.00, -60.00)"), std::string::npos);

  // A second pass that does not meet the acceptance: measured to the end, nothing saved.
  auto strict = run({"max_error_rms_um_after=0.1", "grid.n=5", "pointer.enabled=false"}, "strict");
  ASSERT_FALSE(strict.ok());
  EXPECT_NE(strict.status().message().find("the calibration was not saved"), std::string::npos)
      << strict.status().message();
  EXPECT_TRUE(fs::exists(dir / "strict" / "report.json"));

  EXPECT_EQ(Slurp(cal), original);
}

}  // namespace
}  // namespace insitu
