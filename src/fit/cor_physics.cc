// The linear-drive head fitted to a correction table (cor_physics.h).
//
// Why the forward residual H(p + o(p)) - p in the fit and the offset residual in the report:
// the forward one needs no inversion inside the solver (the head is traced once per node and
// differentiated by Ceres's jets), and near a solution it is the offset residual times the
// head's Jacobian, within a few % of the identity over a lens field; the report inverts the
// fitted head by Newton at every node so that "explained" is in the table's own terms.
//
// Why several starting focal lengths: a reading the head does not explain has local minima
// (the fit trades the two-mirror distortion against c3/c5); each candidate gets the same
// starts, so a wrong reading is not judged on a worse start than the right one.
#include "insitu/fit/cor_physics.h"

#include <ceres/ceres.h>

#include "fit/ceres_support.h"
#include "insitu/optics/newton.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "insitu/optics/scan_head.h"

namespace insitu::fit {
namespace {

using Eigen::Vector2d;

enum Param { kF, kGx, kGy, kC3, kC5, kTilt, kTiltY, kA0, kB0, kPhi, kParams };

// Where command c lands for the parameters p (cor_physics.h: the model).
template <typename T>
void LandT(const T* const* p, const T c[2], T out[2]) {
  using std::cos;
  using std::sin;
  optics::HeadParamsT<T> h;
  h.focal_length_mm = *p[kF];
  h.mirror_separation_mm = T(0);  // moves the chief ray's pupil, not the focal point at z = 0
  h.c3 = *p[kC3];
  h.c5 = *p[kC5];
  h.x_axis_tilt_rad = *p[kTilt];
  h.y_axis_tilt_rad = *p[kTiltY];
  h.beam_offset_x_rad = T(0);
  h.beam_offset_y_rad = T(0);
  h.beam_focal_scale = T(1);
  h.telecentric = true;  // the focal point only: the ray's direction is not needed
  const T a = *p[kGx] * c[0] / *p[kF] + *p[kA0];
  const T b = *p[kGy] * c[1] / *p[kF] + *p[kB0];
  T xy[2], up[3];
  optics::TraceChiefRay(h, a, b, xy, up);
  const T cs = cos(*p[kPhi]), sn = sin(*p[kPhi]);
  out[0] = cs * xy[0] - sn * xy[1];
  out[1] = sn * xy[0] + cs * xy[1];
}

// |H(p + o(p)) - p| at one node.
struct NodeCost {
  NodeCost(const Vector2d& command, const Vector2d& target) : command_(command), target_(target) {}

  template <typename T>
  bool operator()(const T* f, const T* gx, const T* gy, const T* c3, const T* c5, const T* tilt,
                  const T* tilt_y, const T* a0, const T* b0, const T* phi, T* residual) const {
    const T* const p[kParams] = {f, gx, gy, c3, c5, tilt, tilt_y, a0, b0, phi};
    const T c[2] = {T(command_.x()), T(command_.y())};
    T s[2];
    LandT(p, c, s);
    residual[0] = s[0] - T(target_.x());
    residual[1] = s[1] - T(target_.y());
    return true;
  }

  Vector2d command_, target_;
};

void ToParams(const LinearDriveHead& h, double p[kParams]) {
  p[kF] = h.focal_length_mm;
  p[kGx] = h.gain_x;
  p[kGy] = h.gain_y;
  p[kC3] = h.ftheta_c3;
  p[kC5] = h.ftheta_c5;
  p[kTilt] = h.x_axis_tilt_mrad * 1e-3;
  p[kTiltY] = h.y_axis_tilt_mrad * 1e-3;
  p[kA0] = h.x_zero_offset_mrad * 1e-3;
  p[kB0] = h.y_zero_offset_mrad * 1e-3;
  p[kPhi] = h.rotation_mrad * 1e-3;
}

LinearDriveHead FromParams(const double p[kParams]) {
  LinearDriveHead h;
  h.focal_length_mm = p[kF];
  h.gain_x = p[kGx];
  h.gain_y = p[kGy];
  h.ftheta_c3 = p[kC3];
  h.ftheta_c5 = p[kC5];
  h.x_axis_tilt_mrad = p[kTilt] * 1e3;
  h.y_axis_tilt_mrad = p[kTiltY] * 1e3;
  h.x_zero_offset_mrad = p[kA0] * 1e3;
  h.y_zero_offset_mrad = p[kB0] * 1e3;
  h.rotation_mrad = p[kPhi] * 1e3;
  return h;
}

// Half field angles (rad) the focal length starts from: a wide lens, a usual one, a long one.
constexpr double kStartHalfAngles[] = {0.35, 0.2, 0.08};
// The focal length's bounds as half field angles (cor_physics.h, CorPhysicsOptions::lens_mm).
constexpr double kWidestHalfAngle = 0.7, kNarrowestHalfAngle = 0.005;

struct Solved {
  double p[kParams];
  double cost = std::numeric_limits<double>::infinity();
  std::string summary;
};

Solved SolveFrom(double f0, const std::vector<Vector2d>& commands,
                 const std::vector<Vector2d>& targets, const Vector2d& mean_offset,
                 const CorPhysicsOptions& o) {
  Solved s;
  double* p = s.p;
  LinearDriveHead start;
  start.focal_length_mm = f0;
  // The table's mean offset is mostly the zero offsets' shift, -f a0 (and -f b0).
  start.x_zero_offset_mrad = o.fit_zero_offsets ? -mean_offset.x() / f0 * 1e3 : 0.0;
  start.y_zero_offset_mrad = o.fit_zero_offsets ? -mean_offset.y() / f0 * 1e3 : 0.0;
  ToParams(start, p);
  ceres::Problem problem;
  for (size_t k = 0; k < commands.size(); ++k) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<NodeCost, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1>(
            new NodeCost(commands[k], targets[k])),
        nullptr, &p[kF], &p[kGx], &p[kGy], &p[kC3], &p[kC5], &p[kTilt], &p[kTiltY], &p[kA0],
        &p[kB0], &p[kPhi]);
  }
  const double half = 0.5 * o.lens_mm;
  const auto bound = [&](int k, double lo, double hi) {
    problem.SetParameterLowerBound(&p[k], 0, lo);
    problem.SetParameterUpperBound(&p[k], 0, hi);
  };
  bound(kF, half / kWidestHalfAngle, half / kNarrowestHalfAngle);
  bound(kGx, 0.5, 2.0);
  bound(kGy, 0.5, 2.0);
  bound(kC3, -2.0, 2.0);  // HeadGeometry::Validate's range
  bound(kC5, -20.0, 20.0);
  bound(kTilt, -0.05, 0.05);  // 50 mrad, as HeadGeometry::Validate
  bound(kTiltY, -0.05, 0.05);
  bound(kA0, -0.1, 0.1);
  bound(kB0, -0.1, 0.1);
  bound(kPhi, -0.2, 0.2);
  const auto fix = [&](bool fitted, std::initializer_list<int> ks) {
    if (!fitted) {
      for (int k : ks) problem.SetParameterBlockConstant(&p[k]);
    }
  };
  fix(o.fit_gains, {kGx, kGy});
  fix(o.fit_ftheta_distortion, {kC3, kC5});
  fix(o.fit_axis_tilt, {kTilt, kTiltY});
  fix(o.fit_zero_offsets, {kA0, kB0});
  fix(o.fit_rotation, {kPhi});
  const ceres::Solver::Options so = PreciseLmOptions(o.max_iterations);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (summary.IsSolutionUsable()) {
    s.cost = summary.final_cost;
    s.summary = summary.BriefReport();
  }
  return s;
}

}  // namespace

Vector2d LinearDriveHead::Land(const Vector2d& command_mm) const {
  double p[kParams];
  ToParams(*this, p);
  const double* const pp[kParams] = {&p[0], &p[1], &p[2], &p[3], &p[4],
                                     &p[5], &p[6], &p[7], &p[8], &p[9]};
  const double c[2] = {command_mm.x(), command_mm.y()};
  double s[2];
  LandT(pp, c, s);
  return {s[0], s[1]};
}

bool LinearDriveHead::Offset(const Vector2d& p_mm, Vector2d* offset_mm) const {
  // The head's map is smooth and close to the identity times the gains: a few Newton steps
  // reach 1e-9 mm.
  Vector2d c = p_mm;
  if (!optics::InvertMap2d([&](const Vector2d& x) { return Land(x); }, p_mm, 1e-5, 1e-9, &c)) {
    return false;
  }
  *offset_mm = c - p_mm;
  return true;
}

Status CorPhysicsOptions::Validate() const {
  if (!(quantum_mm >= 0)) return InvalidArgument("quantum_mm must be >= 0");
  if (!(std::isfinite(lens_mm) && lens_mm > 0)) {
    return InvalidArgument("lens_mm must be a positive field width, got " +
                           std::to_string(lens_mm));
  }
  if (max_iterations < 1) return InvalidArgument("max_iterations must be >= 1");
  if (stride < 1) return InvalidArgument("stride must be >= 1");
  if (!(min_explained <= 1.0) || !(min_explained_nonlinear <= 1.0) || !(ambiguous_margin >= 0.0)) {
    return InvalidArgument(
        "min_explained and min_explained_nonlinear must be <= 1 and ambiguous_margin >= 0");
  }
  return Status::Ok();
}

Result<CorTableFit> ExplainCorrectionTable(const std::vector<Vector2d>& node_mm,
                                           const std::vector<Vector2d>& offset_mm,
                                           const CorPhysicsOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  if (node_mm.size() != offset_mm.size()) {
    return InvalidArgument(
        "a correction table needs one offset per node: " + std::to_string(node_mm.size()) +
        " nodes, " + std::to_string(offset_mm.size()) + " offsets");
  }
  if (node_mm.size() < 12) {
    return InvalidArgument("a correction table of " + std::to_string(node_mm.size()) +
                           " nodes is too small for the head model (needs 12)");
  }
  double sum2 = 0.0;
  Vector2d mean = Vector2d::Zero();
  for (size_t k = 0; k < node_mm.size(); ++k) {
    if (!node_mm[k].allFinite() || !offset_mm[k].allFinite()) {
      return InvalidArgument("correction table node " + std::to_string(k) + " is not finite");
    }
    sum2 += offset_mm[k].squaredNorm();
    mean += offset_mm[k];
  }
  mean /= static_cast<double>(node_mm.size());
  CorTableFit fit;
  fit.table_rms_mm = std::sqrt(sum2 / node_mm.size());
  if (fit.table_rms_mm == 0.0) {
    fit.summary = "every offset is zero: nothing to explain";
    return fit;
  }

  // The fit's nodes: every stride-th along each axis of the grid the nodes lie on (by rank
  // of their distinct coordinates), all of them when the nodes are not a grid.
  std::vector<double> xs, ys;
  for (const Vector2d& n : node_mm) {
    xs.push_back(n.x());
    ys.push_back(n.y());
  }
  const auto distinct = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
    return v;
  };
  xs = distinct(xs);
  ys = distinct(ys);
  const auto rank = [](const std::vector<double>& v, double q) {
    return static_cast<int>(std::lower_bound(v.begin(), v.end(), q) - v.begin());
  };
  std::vector<Vector2d> commands, targets;
  for (size_t k = 0; k < node_mm.size(); ++k) {
    const int i = rank(xs, node_mm[k].x()), j = rank(ys, node_mm[k].y());
    const bool last_i = i + 1 == static_cast<int>(xs.size());
    const bool last_j = j + 1 == static_cast<int>(ys.size());
    if ((i % options.stride == 0 || last_i) && (j % options.stride == 0 || last_j)) {
      commands.push_back(node_mm[k] + offset_mm[k]);
      targets.push_back(node_mm[k]);
    }
  }

  Solved best;
  for (double half_angle : kStartHalfAngles) {
    Solved s = SolveFrom(0.5 * options.lens_mm / half_angle, commands, targets, mean, options);
    if (s.cost < best.cost) best = s;
  }
  if (!std::isfinite(best.cost)) {
    return FailedPrecondition("the head model could not be fitted to the correction table");
  }
  fit.head = FromParams(best.p);
  fit.summary = best.summary;

  double r2 = 0.0;
  for (size_t k = 0; k < node_mm.size(); ++k) {
    Vector2d model;
    // A node the fitted head cannot reach is explained not at all.
    const double r =
        fit.head.Offset(node_mm[k], &model) ? (model - offset_mm[k]).norm() : offset_mm[k].norm();
    r2 += r * r;
    fit.residual_max_mm = std::max(fit.residual_max_mm, r);
  }
  fit.residual_rms_mm = std::sqrt(r2 / node_mm.size());
  fit.explained = 1.0 - fit.residual_rms_mm / fit.table_rms_mm;
  // What is beyond an affine map: the table less its least-squares affine part.
  Eigen::MatrixXd a(node_mm.size(), 3);
  Eigen::MatrixXd b(node_mm.size(), 2);
  for (size_t k = 0; k < node_mm.size(); ++k) {
    a.row(k) << node_mm[k].x(), node_mm[k].y(), 1.0;
    b.row(k) = offset_mm[k].transpose();
  }
  const Eigen::MatrixXd beyond = b - a * a.colPivHouseholderQr().solve(b);
  fit.nonlinear_rms_mm = std::sqrt(beyond.squaredNorm() / node_mm.size());
  fit.explained_nonlinear =
      fit.nonlinear_rms_mm > 0 ? 1.0 - fit.residual_rms_mm / fit.nonlinear_rms_mm : 0.0;
  return fit;
}

Result<CorReadingChoice> ChooseCorReading(const std::vector<CorReadingCandidate>& candidates,
                                          const CorPhysicsOptions& options) {
  if (candidates.empty()) return InvalidArgument("no readings of the correction table to choose");
  CorReadingChoice choice;
  for (const CorReadingCandidate& c : candidates) {
    auto fit = ExplainCorrectionTable(c.node_mm, c.offset_mm, options);
    if (!fit.ok()) return fit.status().Prefixed(c.name);
    choice.fits.push_back(*fit);
  }
  const int n = static_cast<int>(candidates.size());
  std::vector<int> order(n);
  for (int k = 0; k < n; ++k) order[k] = k;
  // Best first; equal explained fractions keep the candidates' order.
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return choice.fits[a].explained > choice.fits[b].explained;
  });
  choice.best = order[0];
  choice.runner_up = n > 1 ? order[1] : -1;
  const CorTableFit& best = choice.fits[choice.best];
  const auto pct = [&](int k) {
    char s[32];
    std::snprintf(s, sizeof s, "%.1f %%", 100.0 * choice.fits[k].explained);
    return std::string(s);
  };
  const auto named = [&](int k) { return candidates[k].name + " (" + pct(k) + ")"; };
  std::vector<int> documented;
  for (int k : order) {
    if (candidates[k].documented) documented.push_back(k);
  }
  if (best.table_rms_mm == 0.0) {
    // Every reading gives the same table: none contradicts the documented convention.
    choice.chosen = documented.empty() ? order[0] : documented[0];
    choice.decided_by_convention = !documented.empty();
    choice.evidence = "every offset is zero: every reading gives the same table";
    return choice;
  }
  // An affine table (nothing beyond the affine map but rounding) has no distortion to judge
  // by: the readings that explain it tie, and the convention decides among them if it can
  // (the two documented readings, transposes, tie too on a table symmetric enough).
  // Rounding to whole units leaves ~0.41 of a unit rms as a vector beyond any map.
  const bool affine =
      best.nonlinear_rms_mm < std::max(1e-3 * best.table_rms_mm, 0.5 * options.quantum_mm);
  if (best.explained < options.min_explained ||
      (!affine && best.explained_nonlinear < options.min_explained_nonlinear)) {
    char beyond[64];
    std::snprintf(beyond, sizeof beyond, "%.1f %%", 100.0 * best.explained_nonlinear);
    choice.evidence = "the two-mirror head model explains at most " + named(choice.best) +
                      " of the table, " + beyond +
                      " of what is not affine (a scale, shear, turn or shift fits any "
                      "reading): too little to choose a reading by";
    choice.warning = choice.evidence;
    return choice;
  }
  for (int k : order) {
    if (best.explained - choice.fits[k].explained < options.ambiguous_margin) {
      choice.tied.push_back(k);
    }
  }
  if (choice.tied.size() == 1) {
    choice.chosen = choice.best;
    choice.decided_by_physics = true;
    choice.evidence =
        "the two-mirror head model: " + pct(choice.best) +
        (choice.runner_up < 0 ? std::string(", the only reading")
                              : " against " + named(choice.runner_up) + " for the next");
    if (!candidates[choice.best].documented && !documented.empty()) {
      choice.warning =
          "the physics reads the table as " + candidates[choice.best].name +
          ", not in the format's documented convention (best of those: " + named(documented[0]) +
          ")";
    }
    return choice;
  }
  std::string tied_names;
  std::vector<int> tied_documented;
  for (int k : choice.tied) {
    tied_names += (tied_names.empty() ? "" : ", ") + named(k);
    if (candidates[k].documented) tied_documented.push_back(k);
  }
  char margin[32];
  std::snprintf(margin, sizeof margin, "%.0f", 100.0 * options.ambiguous_margin);
  const std::string cannot_tell = "the two-mirror head model cannot tell " + tied_names +
                                  " apart (within " + margin + " points)";
  if (tied_documented.size() == 1) {
    choice.chosen = tied_documented[0];
    choice.decided_by_convention = true;
    choice.evidence = cannot_tell + "; of them only " + candidates[choice.chosen].name +
                      " is the format's documented convention";
    return choice;
  }
  choice.evidence = cannot_tell + (tied_documented.empty()
                                       ? ", and none of them is the format's documented convention"
                                       : ", and more than one of them is documented");
  choice.warning = choice.evidence;
  return choice;
}

}  // namespace insitu::fit
