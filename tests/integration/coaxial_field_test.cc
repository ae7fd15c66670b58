// The coaxial route of the field calibration (seed 001): on a head built differently from its
// design, the coaxial camera looks through the head at a chrome-on-glass reticle laid on the
// stage (turned a degree, off centre), measures where the head points at an 11 x 11 grid and
// at the cells' centres, and seed 001's lookup table must bring the check points (never
// fitted) to <= 3 um in the 10 mm field. Everything is also held against the simulator's
// truth: where the marking beam's chief ray really meets the reticle's top.
#include "job/coaxial_field.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "insitu/hw/sim_backend.h"
#include "insitu/optics/scan_head.h"
#include "insitu/sim/world.h"

namespace insitu {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// The head of config/worlds/as_built.yaml, in part: f 256.2 mm for 255 (+0.47 %), c3 0.04
// against the design's 0, the X mirror's axis tilted 1 mrad, a 0.3 mrad zero error on X;
// the reticle (1 mm pitch, 9 um lines, 2.3 mm glass) laid by hand: 1 deg, 0.35 / -0.22 mm.
sim::WorldOptions AsBuiltOverReticle() {
  sim::WorldOptions w;
  w.scan_head.optics.focal_length_mm = 256.2;
  w.scan_head.optics.ftheta_c3 = 0.04;
  w.scan_head.optics.x_axis_tilt_mrad = 1.0;
  w.scan_head.x_zero_offset_mrad = 0.3;
  w.part.kind = "grid_plate";
  w.part.position_mm = {0.35, -0.22};
  w.part.rotation_deg = 1.0;
  return w;
}

job::CoaxialFieldOptions Options(const sim::WorldOptions& w) {
  job::CoaxialFieldOptions o;
  o.surface_z_mm = w.stage.z_mm + w.part.grid_plate_thickness_mm;  // the reticle's top
  return o;
}

// The rigid motion (rotation, translation) taking `from` onto `to` by least squares.
Eigen::Isometry2d Rigid(const std::vector<Vector2d>& from, const std::vector<Vector2d>& to) {
  Vector2d cf = Vector2d::Zero(), ct = Vector2d::Zero();
  for (size_t i = 0; i < from.size(); ++i) cf += from[i], ct += to[i];
  cf /= from.size();
  ct /= to.size();
  double c = 0, s = 0;
  for (size_t i = 0; i < from.size(); ++i) {
    const Vector2d a = from[i] - cf, b = to[i] - ct;
    c += a.dot(b);
    s += a.x() * b.y() - a.y() * b.x();
  }
  Eigen::Isometry2d t = Eigen::Isometry2d::Identity();
  t.linear() = Eigen::Rotation2Dd(std::atan2(s, c)).toRotationMatrix();
  t.translation() = ct - t.linear() * cf;
  return t;
}

struct Errors {
  double rms_um = 0.0, max_um = 0.0;
};
Errors Stats(const std::vector<Vector2d>& d) {
  Errors e;
  for (const Vector2d& v : d) {
    e.rms_um += v.squaredNorm();
    e.max_um = std::max(e.max_um, v.norm() * 1e3);
  }
  e.rms_um = std::sqrt(e.rms_um / d.size()) * 1e3;
  return e;
}

TEST(CoaxialField, AsBuiltHeadToThreeMicrometresInTenMillimetres) {
  const sim::WorldOptions w = AsBuiltOverReticle();
  ASSERT_TRUE(w.Validate().ok());
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  std::vector<std::string> warnings;
  const auto start = std::chrono::steady_clock::now();
  auto r = job::MeasureCoaxialField(machine, Options(w), {}, &warnings);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  for (const std::string& s : warnings) std::printf("warning: %s\n", s.c_str());
  ASSERT_EQ(r->grid.size(), 121u);
  ASSERT_EQ(r->check.size(), 100u);
  ASSERT_EQ(r->check_after.size(), 100u);

  // The truth: where the marking beam's chief ray crosses the reticle's top (the commands'
  // focus height) for each command, through the as-built head.
  optics::HeadModel head;
  head.design = w.scan_head.design;
  head.built = w.scan_head.optics;
  head.x_zero_offset_mrad = w.scan_head.x_zero_offset_mrad;
  head.y_zero_offset_mrad = w.scan_head.y_zero_offset_mrad;
  const auto land = [&](const Vector3d& cmd) {
    Vector3d spot;
    EXPECT_TRUE(head.Spot(cmd, {}, &spot));
    return Vector2d(spot.head<2>());
  };
  // The truth's own field error modulo a rigid motion (fitted on the nodes, as the job does).
  std::vector<Vector2d> node_cmd, node_true, node_meas;
  for (const fit::GalvoSample& g : r->grid) {
    node_cmd.push_back(g.cmd.head<2>());
    node_true.push_back(land(g.cmd));
    node_meas.push_back(g.meas);
  }
  const Eigen::Isometry2d true_to_cmd = Rigid(node_true, node_cmd);
  std::vector<Vector2d> true_before, meas_vs_truth, true_after;
  for (const fit::GalvoSample& g : r->check) {
    const Vector2d t = true_to_cmd * land(g.cmd);
    true_before.push_back(t - g.cmd.head<2>());
    meas_vs_truth.push_back(g.meas - t);
  }
  for (size_t i = 0; i < r->check_after.size(); ++i) {
    const Vector2d t = true_to_cmd * land(r->check_after_commands[i]);
    true_after.push_back(t - r->check_after[i].cmd.head<2>());
    meas_vs_truth.push_back(r->check_after[i].meas - t);
  }
  for (size_t i = 0; i < node_meas.size(); ++i) {
    meas_vs_truth.push_back(node_meas[i] - true_to_cmd * node_true[i]);
  }
  const Errors truth_before = Stats(true_before), truth_after = Stats(true_after);
  const Errors measurement = Stats(meas_vs_truth);
  std::printf(
      "coaxial field, 10 mm, %d frames in %.1f s: camera %.4f um/px (true %.4f), %.3f deg "
      "(true %.3f), >= %d crosses per frame, cross rms %.3f um, index margin %.1f um\n"
      "  check points before: measured %.2f um rms / %.2f max, truth %.2f / %.2f\n"
      "  check points after:  measured %.2f um rms / %.2f max, truth %.2f / %.2f\n"
      "  measured aims vs truth (modulo the rigid motion): %.3f um rms, %.3f um max\n",
      r->frames, seconds, r->pixel_um, w.scan_head.coaxial.pixel_on_part_um, r->rotation_deg,
      w.scan_head.coaxial.rotation_deg, r->min_crosses_seen, r->cross_residual_um,
      r->max_index_error_um, r->rms_um_before, r->max_um_before, truth_before.rms_um,
      truth_before.max_um, r->rms_um_after, r->max_um_after, truth_after.rms_um, truth_after.max_um,
      measurement.rms_um, measurement.max_um);

  // The as-built head really is off: +0.47 % of scale over the check points' rms radius
  // (4.06 mm: x, y in +-0.5..4.5) is 19 um rms, at their corners (6.36 mm) 30 um, once the
  // rigid motion is out. The measurement must see it as the truth has it.
  EXPECT_GT(truth_before.rms_um, 10.0);
  EXPECT_NEAR(r->rms_um_before, truth_before.rms_um, 0.5);
  EXPECT_NEAR(r->max_um_before, truth_before.max_um, 1.0);
  // Each aim from ~20 crosses at ~0.005 px (0.03 um) each, through a similarity: a few
  // hundredths of a um of noise. But the head itself settles differently after every jump
  // (scan_head.repeatability_urad: 2 urad rms per axis, 0.51 um at 256 mm, 0.72 um as a 2D
  // rms), which the measurement sees and this deterministic truth model does not: the two
  // differ by that, 0.72 um rms (20 % margin and 0.1 um for the rest), and by under 4 of its
  // sigmas (2.9 um) at the worst of ~420 aims.
  EXPECT_LT(measurement.rms_um, 0.72 * 1.2 + 0.1);
  EXPECT_LT(measurement.max_um, 2.9);
  // Seed 001: <= 3 um in a 10 mm field after the second closed-loop pass, by the camera and
  // in the truth. What the table leaves is bilinear interpolation of a smooth field on 1 mm
  // cells (curvature of the two-mirror field, c3: well under a um) plus the measurement.
  EXPECT_LE(r->rms_um_after, 3.0);
  EXPECT_LE(r->max_um_after, 3.0);
  EXPECT_LE(truth_after.rms_um, 3.0);
  EXPECT_LE(truth_after.max_um, 3.0);
  // The measured after holds the second aim's settling error (0.72 um rms), the model's not.
  EXPECT_NEAR(r->rms_um_after, truth_after.rms_um, 0.72 + 0.2);
  // The camera calibrated on the reticle: 5 um pixels to what ~20 crosses per frame over
  // 321 frames give (1e-4 of scale), and the sensor's 0.4 deg turn against the galvo frame as
  // the rigid fit sets it: that frame takes the field's own mean rotation as its axes, and the
  // tilted X axis shears the field by tau a / 2 (rotation part tau / 4 = 0.25 mrad,
  // 0.014 deg); 0.02 deg.
  EXPECT_NEAR(r->pixel_um, w.scan_head.coaxial.pixel_on_part_um, 5e-3);
  EXPECT_NEAR(r->rotation_deg, w.scan_head.coaxial.rotation_deg, 0.02);
  // The reticle lies where it was put: the rigid fit's rotation is its 1 deg (plus what the
  // zero error and the tilt turn, well under 0.05 deg).
  const double placed =
      std::atan2(r->galvo_from_reticle.linear()(1, 0), r->galvo_from_reticle.linear()(0, 0)) *
      180.0 / M_PI;
  EXPECT_NEAR(std::abs(placed), 1.0, 0.05);
  // The table corrects by what was measured: at the corner node +0.47 % of 5 sqrt 2 mm.
  const Vector2d corner = r->correction.At(5.0, 5.0);
  EXPECT_GT(corner.norm() * 1e3, 20.0);
  EXPECT_LT(corner.norm() * 1e3, 45.0);
  // No wall-clock bound here: about 90 s alone on two cores, more beside another integration
  // test; the time is printed above and ctest's TIMEOUT guards against a hang. Speed claims
  // live in bench/.
}

// Nothing to look at: a plain plate under the head. The error names the reticle.
TEST(CoaxialField, NoReticleUnderTheHead) {
  sim::WorldOptions w = AsBuiltOverReticle();
  w.part.kind = "plane";
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  job::CoaxialFieldOptions o;
  o.surface_z_mm = w.part.plane_thickness_mm;
  auto r = job::MeasureCoaxialField(machine, o, {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(r.status().message().find("no reticle"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("grid plate"), std::string::npos);
}

// A reticle smaller than the field (4 mm: 3 x 3 crosses): the first point whose view holds
// too few crosses is named, and nothing is fitted.
TEST(CoaxialField, ReticleSmallerThanTheField) {
  sim::WorldOptions w = AsBuiltOverReticle();
  w.part.grid_plate_size_mm = 4.0;
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  job::CoaxialFieldOptions o = Options(w);
  o.n = 5;  // 2.5 mm steps: the first ring already looks past the glass
  auto r = job::MeasureCoaxialField(machine, o, {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(r.status().message().find("crosses"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("the reticle must cover the field"), std::string::npos);
  std::printf("%s\n", r.status().message().c_str());
}

TEST(CoaxialField, NoCoaxialCamera) {
  sim::WorldOptions w = AsBuiltOverReticle();
  w.scan_head.coaxial.present = false;
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  auto r = job::MeasureCoaxialField(machine, Options(w), {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(r.status().message().find("no coaxial camera"), std::string::npos)
      << r.status().message();
}

TEST(CoaxialField, BadOptionsAndAGridBeyondTheField) {
  const sim::WorldOptions w = AsBuiltOverReticle();
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  job::CoaxialFieldOptions o = Options(w);
  o.n = 1;
  auto r = job::MeasureCoaxialField(machine, o, {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("n must be"), std::string::npos) << r.status().message();
  o = Options(w);
  o.max_index_error_fraction = 0.5;  // seed 001: half a pitch is already ambiguous
  r = job::MeasureCoaxialField(machine, o, {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("max_index_error_fraction"), std::string::npos);
  o = Options(w);
  o.half_size_mm = 80.0;  // the head's field is +-70 mm
  r = job::MeasureCoaxialField(machine, o, {}, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("beyond the head's field"), std::string::npos);
}

// Cancelled from outside between frames.
TEST(CoaxialField, Cancelled) {
  const sim::WorldOptions w = AsBuiltOverReticle();
  auto world = std::make_shared<sim::SimWorld>(w);
  hw::Machine machine = hw::MakeSimMachine(world);
  std::atomic<bool> cancel{false};
  job::RunOptions run;
  run.cancel = &cancel;
  int frames = 0;
  run.progress = [&](const job::JobProgress& p) {
    EXPECT_EQ(p.phase, "coaxial field");
    frames = static_cast<int>(p.done);
    if (p.done >= 1) cancel = true;
  };
  auto r = job::MeasureCoaxialField(machine, Options(w), run, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled);
  EXPECT_EQ(frames, 1);  // no frame after the flag
}

}  // namespace
}  // namespace insitu
