// The coaxial route of the field calibration (seed 001). See coaxial_field.h for the physics
// and the frames.
//
// One frame. The crosses' centres (vision/crosses.h) go into the image as seen from above,
// q = (u - u_c, -(v - v_c)) with (u_c, v_c) the image centre, so the head's aim is q = 0. The
// lattice's direction in q is the circular mean of the crosses' line directions (4 phi folds
// the two lines of every cross together), its pitch in pixels the median distance between
// neighbours; each cross's lattice index relative to the cross nearest the centre is then
// its offset rotated onto the lattice and divided by the pitch, rounded. A similarity
// reticle = s R(alpha) q + t, fitted by least squares over every cross in view, gives the aim
// (t: q = 0), the camera's scale s and its rotation alpha against the reticle. A similarity
// and not a homography: over the camera's 5 mm the f-theta images the surface with one
// scale (its distortion over the field is what is measured, ~1e-3; across 5 mm it changes the
// local scale by ~1e-5), and 4 parameters from ~20 crosses keep the aim's noise down.
//
// Seed 001's table. The bilinear model (fit::BilinearFieldModel) holds the measured error at
// the nodes; the correction at a node is the command its inverse gives for that node, minus
// the node (FieldModel::CommandFor); between nodes the offsets are interpolated linearly
// (seed 001 sec. 4.3: Delta_A + (Delta_B - Delta_A)(x - A) / (B - A)). The second pass sends
// check point + table offset, which is what a head running the table does.
#include "job/coaxial_field.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "insitu/core/log.h"
#include "insitu/core/robust.h"
#include "job/progress.h"

namespace insitu::job {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

std::string Num(double v, int digits = 3) {
  char b[48];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

std::string At(const Vector3d& c) {
  return "(" + Num(c.x(), 3) + ", " + Num(c.y(), 3) + ", " + Num(c.z(), 3) + ") mm";
}

Eigen::Matrix2d Rot(double a) { return Eigen::Rotation2Dd(a).toRotationMatrix(); }

// What one frame says about the aim, in the frame's own lattice (origin at its reference
// cross, the cross nearest the image centre).
struct FrameFit {
  Vector2d aim_local = Vector2d::Zero();  // mm
  double scale_mm_per_px = 0.0;
  double rotation_rad = 0.0;     // q to the reticle
  double lattice_rad = 0.0;      // the reticle's x lines, in q
  double residual_ss_mm2 = 0.0;  // crosses about the similarity
  int crosses = 0;
};

// A similarity b = s R a + t (or, with `reflect`, s R diag(1, -1) a + t) by least squares:
// the 2 x 2 linear part and t. At least 2 pairs.
struct Similarity {
  Eigen::Matrix2d linear = Eigen::Matrix2d::Identity();
  Vector2d t = Vector2d::Zero();
  double rms = 0.0;
  Vector2d operator()(const Vector2d& a) const { return linear * a + t; }
};

Similarity FitSimilarity(const std::vector<Vector2d>& a, const std::vector<Vector2d>& b, bool scale,
                         bool reflect) {
  const size_t n = a.size();
  Vector2d ca = Vector2d::Zero(), cb = Vector2d::Zero();
  for (size_t k = 0; k < n; ++k) ca += a[k], cb += b[k];
  ca /= n;
  cb /= n;
  const Eigen::Matrix2d flip =
      reflect ? Eigen::Vector2d(1, -1).asDiagonal().toDenseMatrix() : Eigen::Matrix2d::Identity();
  // Rotation angle maximising sum b' . R a' (2D Procrustes), then the best scale.
  double sc = 0.0, ss = 0.0, aa = 0.0;
  for (size_t k = 0; k < n; ++k) {
    const Vector2d p = flip * (a[k] - ca), q = b[k] - cb;
    sc += p.dot(q);
    ss += p.x() * q.y() - p.y() * q.x();
    aa += p.squaredNorm();
  }
  const double angle = std::atan2(ss, sc);
  const double s = scale && aa > 0 ? std::hypot(sc, ss) / aa : 1.0;
  Similarity f;
  f.linear = s * Rot(angle) * flip;
  f.t = cb - f.linear * ca;
  double e2 = 0.0;
  for (size_t k = 0; k < n; ++k) e2 += (f(a[k]) - b[k]).squaredNorm();
  f.rms = std::sqrt(e2 / std::max<size_t>(1, n));
  return f;
}

// Places the image centre on the reticle from the crosses in view. `lattice_ref`: the
// lattice direction of the first frame (radians in q), or null for the first frame itself.
Result<FrameFit> FitFrame(const std::vector<vision::Cross>& found, int width, int height,
                          const CoaxialFieldOptions& o, const double* lattice_ref) {
  const double cu = 0.5 * (width - 1), cv = 0.5 * (height - 1);
  const double flip = o.image_mirrored ? 1.0 : -1.0;
  std::vector<Vector2d> q;
  double c4 = 0.0, s4 = 0.0;
  for (const vision::Cross& c : found) {
    q.emplace_back(c.centre_px.x() - cu, flip * (c.centre_px.y() - cv));
    for (double deg : {c.angle_deg, c.angle2_deg}) {
      const double a = flip * deg * M_PI / 180.0;  // the line's direction in q
      c4 += std::cos(4.0 * a);
      s4 += std::sin(4.0 * a);
    }
  }
  if (static_cast<int>(q.size()) < std::max(2, o.min_crosses)) {
    return FailedPrecondition(std::to_string(q.size()) + " crosses in view (need " +
                              std::to_string(o.min_crosses) + ")");
  }
  double phi = 0.25 * std::atan2(s4, c4);
  if (lattice_ref != nullptr) phi += 0.5 * M_PI * std::round((*lattice_ref - phi) / (0.5 * M_PI));
  // Pitch in pixels: the median distance of a cross to its nearest neighbour.
  std::vector<double> nearest;
  for (size_t i = 0; i < q.size(); ++i) {
    double d = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < q.size(); ++j) {
      if (j != i) d = std::min(d, (q[i] - q[j]).norm());
    }
    nearest.push_back(d);
  }
  const double pitch_px = Median(nearest);
  size_t ref = 0;
  for (size_t i = 1; i < q.size(); ++i) {
    if (q[i].norm() < q[ref].norm()) ref = i;
  }
  // Lattice indices; a cross off the lattice (a false detection, dust) is left out.
  const Eigen::Matrix2d onto = Rot(-phi);
  std::vector<Vector2d> from, to;
  for (size_t i = 0; i < q.size(); ++i) {
    const Vector2d d = onto * (q[i] - q[ref]) / pitch_px;
    const Vector2d idx(std::round(d.x()), std::round(d.y()));
    if ((d - idx).cwiseAbs().maxCoeff() > 0.25) continue;
    from.push_back(q[i]);
    to.push_back(o.reticle_pitch_mm * idx);
  }
  Similarity f;
  for (int pass = 0; pass < 2; ++pass) {
    if (static_cast<int>(from.size()) < o.min_crosses) {
      return FailedPrecondition(std::to_string(from.size()) +
                                " crosses on the reticle's lattice (need " +
                                std::to_string(o.min_crosses) + ")");
    }
    f = FitSimilarity(from, to, true, false);
    if (pass == 1) break;
    // Gross outliers only: a cross more than 3 px (or 4 rms) off the similarity.
    const double scale = f.linear.col(0).norm();
    const double limit = std::max(4.0 * f.rms, 3.0 * scale);
    std::vector<Vector2d> keep_from, keep_to;
    for (size_t i = 0; i < from.size(); ++i) {
      if ((f(from[i]) - to[i]).norm() <= limit) {
        keep_from.push_back(from[i]);
        keep_to.push_back(to[i]);
      }
    }
    from.swap(keep_from);
    to.swap(keep_to);
  }
  FrameFit fit;
  fit.aim_local = f.t;
  fit.scale_mm_per_px = f.linear.col(0).norm();
  fit.rotation_rad = std::atan2(f.linear(1, 0), f.linear(0, 0));
  fit.lattice_rad = phi;
  fit.residual_ss_mm2 = f.rms * f.rms * from.size();
  fit.crosses = static_cast<int>(from.size());
  return fit;
}

// Aims the head (every beam off) at a command: a list of one jump, held for the settle time.
Status Aim(hw::Scanner& scanner, const Vector3d& cmd, double settle_us) {
  hw::GalvoList list;
  list.entries.push_back({hw::GalvoListEntry::Kind::kJump, cmd});
  list.jump_delay_us = settle_us;
  return scanner.ExecuteList(list);
}

}  // namespace

Status CoaxialFieldOptions::Validate() const {
  const auto bad = [](const std::string& field, const std::string& rule, double v) {
    return InvalidArgument("coaxial field: " + field + " must be " + rule + ", got " + Num(v, 6));
  };
  if (!(half_size_mm > 0 && half_size_mm < 1000))
    return bad("half_size_mm", "in (0, 1000)", half_size_mm);
  if (n < 2 || n > 65) return bad("n", "in 2..65", n);
  if (!std::isfinite(surface_z_mm)) return bad("surface_z_mm", "finite", surface_z_mm);
  if (!(reticle_pitch_mm > 0 && reticle_pitch_mm < 100)) {
    return bad("reticle_pitch_mm", "in (0, 100)", reticle_pitch_mm);
  }
  if (!(exposure_us >= 1 && exposure_us <= 1e6))
    return bad("exposure_us", "in [1, 1e6]", exposure_us);
  if (!(settle_us >= 0 && settle_us <= 1e6)) return bad("settle_us", "in [0, 1e6]", settle_us);
  if (min_crosses < 3) return bad("min_crosses", ">= 3", min_crosses);
  if (!(max_index_error_fraction > 0 && max_index_error_fraction < 0.5)) {
    return bad("max_index_error_fraction", "in (0, 0.5) (seed 001 sec. 3.3: half a pitch)",
               max_index_error_fraction);
  }
  const Status crosses_ok = crosses.Validate();
  if (!crosses_ok.ok()) return crosses_ok.Prefixed("coaxial field");
  return Status::Ok();
}

Result<CoaxialFieldResult> MeasureCoaxialField(hw::Machine& machine, const CoaxialFieldOptions& o,
                                               const RunOptions& run,
                                               std::vector<std::string>* warnings) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  if (!machine.scanner) return FailedPrecondition("coaxial field: the machine has no scan head");
  if (!machine.coaxial) {
    return FailedPrecondition(
        "coaxial field: the machine has no coaxial camera (nothing on the scan head's camera "
        "port): the coaxial route of the field calibration needs one; use the side camera's "
        "route");
  }
  const hw::ScannerInfo head = machine.scanner->info();
  if (head.field_half_size_mm > 0 && o.half_size_mm > head.field_half_size_mm) {
    return InvalidArgument("coaxial field: half_size_mm " + Num(o.half_size_mm, 2) +
                           " mm is beyond the head's field of +-" +
                           Num(head.field_half_size_mm, 2) + " mm");
  }
  if (head.focus_range_mm > 0 && std::abs(o.surface_z_mm) > head.focus_range_mm) {
    return InvalidArgument("coaxial field: surface_z_mm " + Num(o.surface_z_mm, 2) +
                           " mm is beyond the head's focus range of +-" +
                           Num(head.focus_range_mm, 2) + " mm");
  }
  auto log = Logger("job");
  const auto warn = [&](const std::string& w) {
    log->warn("coaxial field: {}", w);
    if (warnings != nullptr) warnings->push_back("coaxial field: " + w);
  };
  hw::Camera& coax = *machine.coaxial;
  INSITU_RETURN_IF_ERROR(coax.SetExposure(o.exposure_us).Prefixed("coaxial field: camera"));

  // The points: grid nodes (row-major from -half), then the cells' centres.
  const double z = o.surface_z_mm;
  const double step = 2.0 * o.half_size_mm / (o.n - 1);
  std::vector<Vector3d> nodes, checks;
  for (int iy = 0; iy < o.n; ++iy) {
    for (int ix = 0; ix < o.n; ++ix) {
      nodes.emplace_back(-o.half_size_mm + ix * step, -o.half_size_mm + iy * step, z);
    }
  }
  if (o.check_points) {
    for (int iy = 0; iy + 1 < o.n; ++iy) {
      for (int ix = 0; ix + 1 < o.n; ++ix) {
        checks.emplace_back(-o.half_size_mm + (ix + 0.5) * step,
                            -o.half_size_mm + (iy + 0.5) * step, z);
      }
    }
  }
  // Visit order: the field centre first (seed 001 sec. 6: the plate's centre names the
  // crosses), then outward, so each prediction extends a little beyond what was measured.
  struct Visit {
    Vector3d cmd;
    int node = -1, check = -1;  // which point it measures (-1: neither, the centre frame)
  };
  std::vector<Visit> order;
  const Vector3d centre(0.0, 0.0, z);
  const bool centre_is_node = o.n % 2 == 1;
  if (!centre_is_node) order.push_back({centre, -1, -1});
  for (size_t i = 0; i < nodes.size(); ++i) order.push_back({nodes[i], static_cast<int>(i), -1});
  for (size_t i = 0; i < checks.size(); ++i) order.push_back({checks[i], -1, static_cast<int>(i)});
  // Distances to the nm, so that equal rings stay in the layout's order.
  const auto ring = [](const Visit& v) { return std::llround(v.cmd.head<2>().norm() * 1e6); };
  std::stable_sort(order.begin(), order.end(),
                   [&](const Visit& a, const Visit& b) { return ring(a) < ring(b); });

  const size_t total = order.size() + (o.second_pass ? checks.size() : 0);
  PhaseProgress progress(run, "coaxial field", "frames", static_cast<double>(total));
  const auto cancelled = [&] { return run.cancel != nullptr && run.cancel->load(); };

  CoaxialFieldResult result;
  result.min_crosses_seen = std::numeric_limits<int>::max();
  std::vector<double> scales, rotations;
  double residual_ss = 0.0;
  int residual_n = 0;
  bool have_lattice = false;
  double lattice_ref = 0.0;
  double first_rotation = 0.0;
  double worst_frame_rms_um = 0.0;  // crosses about their frame's similarity
  Vector3d worst_frame_at = Vector3d::Zero();
  // Aims measured so far, for the numbering: command xy -> reticle (mm).
  std::vector<Vector2d> known_cmd, known_aim;

  // One frame at `cmd`: the aim on the reticle, numbered from `predicted` (reticle frame;
  // null for the first frame, which defines the numbering).
  const auto measure = [&](const Vector3d& cmd, const Vector2d* predicted) -> Result<Vector2d> {
    if (cancelled()) return Status(StatusCode::kCancelled, "coaxial field: cancelled");
    INSITU_RETURN_IF_ERROR(Aim(*machine.scanner, cmd, o.settle_us).Prefixed("coaxial field"));
    INSITU_ASSIGN_OR_RETURN(Frame frame, coax.Grab());
    ++result.frames;
    progress.Update(result.frames);
    auto found = vision::FindCrosses(vision::ViewOf(frame), o.crosses);
    if (!found.ok()) return found.status().Prefixed("coaxial field at " + At(cmd));
    auto fit =
        FitFrame(*found, frame.width, frame.height, o, have_lattice ? &lattice_ref : nullptr);
    if (!fit.ok()) {
      if (predicted == nullptr) {
        return FailedPrecondition(
            "coaxial field: no reticle in view at the field centre " + At(cmd) + ": " +
            fit.status().message() + "; lay the grid plate (reticle of + crosses, pitch " +
            Num(o.reticle_pitch_mm, 3) +
            " mm) under the head with its top at surface_z_mm = " + Num(z, 3) + " mm");
      }
      return FailedPrecondition("coaxial field: at " + At(cmd) + " the coaxial image shows " +
                                fit.status().message() +
                                ": the reticle must cover the field and the camera's view "
                                "around it");
    }
    if (!have_lattice) {
      have_lattice = true;
      lattice_ref = fit->lattice_rad;
      first_rotation = fit->rotation_rad;
    }
    Vector2d aim = fit->aim_local;
    if (predicted != nullptr) {
      const Vector2d shift = ((*predicted - aim) / o.reticle_pitch_mm).array().round().matrix();
      aim += o.reticle_pitch_mm * shift;
      const double off = (aim - *predicted).norm();
      result.max_index_error_um = std::max(result.max_index_error_um, off * 1e3);
      if (off > o.max_index_error_fraction * o.reticle_pitch_mm) {
        return FailedPrecondition(
            "coaxial field: at " + At(cmd) + " the aim lies " + Num(off * 1e3, 1) +
            " um from where the points measured so far put it, more than " +
            Num(o.max_index_error_fraction, 2) +
            " of the reticle's pitch: which cross is which is ambiguous (seed 001 sec. 3.3); "
            "a finer grid (larger n) or a coarser reticle pitch");
      }
    }
    scales.push_back(fit->scale_mm_per_px);
    // Turns relative to the first frame's (no wrap at +-180 deg whatever the placement).
    rotations.push_back(std::remainder(fit->rotation_rad - first_rotation, 2.0 * M_PI));
    const double frame_rms_um = std::sqrt(fit->residual_ss_mm2 / fit->crosses) * 1e3;
    if (frame_rms_um > worst_frame_rms_um) {
      worst_frame_rms_um = frame_rms_um;
      worst_frame_at = cmd;
    }
    residual_ss += fit->residual_ss_mm2;
    residual_n += fit->crosses;
    result.min_crosses_seen = std::min(result.min_crosses_seen, fit->crosses);
    return aim;
  };
  // Where the reticle is expected under a command, from the aims measured so far.
  const auto predict = [&](const Vector2d& cmd) -> Vector2d {
    if (known_cmd.size() == 1) {
      // One point: the camera taken as turned like the galvo frame (its nominal mounting;
      // the next points measure it), so the reticle turns by the frame's rotation.
      return known_aim[0] + Rot(first_rotation) * (cmd - known_cmd[0]);
    }
    return FitSimilarity(known_cmd, known_aim, true, false)(cmd);
  };

  std::vector<Vector2d> node_aim(nodes.size()), check_aim(checks.size());
  for (const Visit& v : order) {
    Vector2d predicted;
    if (!known_cmd.empty()) predicted = predict(v.cmd.head<2>());
    INSITU_ASSIGN_OR_RETURN(Vector2d aim, measure(v.cmd, known_cmd.empty() ? nullptr : &predicted));
    known_cmd.push_back(v.cmd.head<2>());
    known_aim.push_back(aim);
    if (v.node >= 0) node_aim[v.node] = aim;
    if (v.check >= 0) check_aim[v.check] = aim;
  }

  // The reticle into the galvo frame: a rigid fit over the nodes (its placement is no error,
  // its scale is the standard). An image mirrored against the galvo frame shows here.
  std::vector<Vector2d> node_cmd;
  for (const Vector3d& c : nodes) node_cmd.push_back(c.head<2>());
  const Similarity rigid = FitSimilarity(node_aim, node_cmd, false, false);
  const Similarity mirrored = FitSimilarity(node_aim, node_cmd, false, true);
  if (mirrored.rms < 0.1 * rigid.rms) {
    return FailedPrecondition(
        "coaxial field: the reticle's positions fit the commands only mirrored (rms " +
        Num(mirrored.rms * 1e3, 1) + " um against " + Num(rigid.rms * 1e3, 1) +
        " um): the coaxial image is mirrored against the galvo frame; set image_mirrored");
  }
  result.galvo_from_reticle = Eigen::Isometry2d::Identity();
  result.galvo_from_reticle.linear() = rigid.linear;
  result.galvo_from_reticle.translation() = rigid.t;
  result.rigid_rms_um = rigid.rms * 1e3;
  for (size_t i = 0; i < nodes.size(); ++i) result.grid.push_back({nodes[i], rigid(node_aim[i])});
  for (size_t i = 0; i < checks.size(); ++i) {
    result.check.push_back({checks[i], rigid(check_aim[i])});
  }
  const double grid_rad = std::atan2(rigid.linear(1, 0), rigid.linear(0, 0));
  result.pixel_um = Median(scales) * 1e3;
  result.pixel_um_spread = (*std::max_element(scales.begin(), scales.end()) -
                            *std::min_element(scales.begin(), scales.end())) *
                           1e3;
  result.rotation_deg =
      std::remainder(Median(rotations) + first_rotation + grid_rad, 2.0 * M_PI) * 180.0 / M_PI;
  result.cross_residual_um = std::sqrt(residual_ss / std::max(1, residual_n)) * 1e3;

  // Seed 001's table on the nodes.
  INSITU_ASSIGN_OR_RETURN(fit::BilinearFieldModel model, fit::BilinearFieldModel::Fit(result.grid));
  std::vector<double> xs, ys;
  for (int i = 0; i < o.n; ++i) {
    xs.push_back(nodes[i].x());
    ys.push_back(nodes[static_cast<size_t>(i) * o.n].y());
  }
  std::vector<Vector2d> offsets;
  for (const Vector3d& node : nodes) {
    Vector3d cmd;
    if (!model.CommandFor(node, &cmd)) {
      return Status(StatusCode::kInternal,
                    "coaxial field: the measured field cannot be inverted at " + At(node));
    }
    offsets.push_back(cmd.head<2>() - node.head<2>());
  }
  INSITU_ASSIGN_OR_RETURN(result.correction, optics::GridTable::Make(xs, ys, offsets));

  const auto stats = [](const std::vector<fit::GalvoSample>& s, double* rms, double* max) {
    double e2 = 0.0;
    *max = 0.0;
    for (const fit::GalvoSample& g : s) {
      const double e = (g.meas - g.cmd.head<2>()).norm() * 1e3;
      e2 += e * e;
      *max = std::max(*max, e);
    }
    *rms = s.empty() ? 0.0 : std::sqrt(e2 / s.size());
  };
  stats(result.check, &result.rms_um_before, &result.max_um_before);
  log->info(
      "coaxial field: camera {:.4f} um/px, {:.3f} deg; {} frames, >= {} crosses, cross rms "
      "{:.3f} um; check points before: {:.2f} um rms, {:.2f} um max",
      result.pixel_um, result.rotation_deg, result.frames, result.min_crosses_seen,
      result.cross_residual_um, result.rms_um_before, result.max_um_before);

  // Seed 001's second pass: the check points through the table, measured again.
  if (o.second_pass && !checks.empty()) {
    const Eigen::Matrix2d inv_linear = rigid.linear.transpose();  // rotation
    for (const Vector3d& target : checks) {
      const Vector2d offset = result.correction.At(target.x(), target.y());
      const Vector3d cmd(target.x() + offset.x(), target.y() + offset.y(), z);
      const Vector2d predicted = inv_linear * (target.head<2>() - rigid.t);
      INSITU_ASSIGN_OR_RETURN(Vector2d aim, measure(cmd, &predicted));
      result.check_after.push_back({target, rigid(aim)});
      result.check_after_commands.push_back(cmd);
    }
    stats(result.check_after, &result.rms_um_after, &result.max_um_after);
    log->info("coaxial field: check points after the table: {:.2f} um rms, {:.2f} um max",
              result.rms_um_after, result.max_um_after);
  }
  // A frame whose crosses scatter about their similarity by more than 0.2 px (~30 times what
  // detection noise gives): dust or a damaged line on the reticle there.
  if (worst_frame_rms_um > 0.2 * result.pixel_um) {
    warn("the crosses at " + At(worst_frame_at) + " scatter by " + Num(worst_frame_rms_um, 2) +
         " um rms about their lattice: dust or a damaged reticle there?");
  }
  if (result.pixel_um_spread > 0.01 * result.pixel_um) {
    warn("the camera's scale varies by " + Num(result.pixel_um_spread, 3) + " um/px over the " +
         "field (more than 1 %): is the reticle flat and in focus everywhere?");
  }
  return result;
}

}  // namespace insitu::job
