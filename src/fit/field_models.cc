#include "insitu/fit/field_models.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <ceres/ceres.h>

#include "fit/ceres_support.h"
#include "insitu/optics/newton.h"

namespace insitu::fit {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// Grid coordinates are commands: equal within 1 um.
constexpr double kNodeTolMm = 1e-3;

std::vector<double> DistinctSorted(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  std::vector<double> out;
  for (double x : v) {
    if (out.empty() || x - out.back() > kNodeTolMm) out.push_back(x);
  }
  return out;
}

int IndexOf(const std::vector<double>& grid, double x) {
  const auto it = std::lower_bound(grid.begin(), grid.end(), x - kNodeTolMm);
  if (it == grid.end() || std::abs(*it - x) > kNodeTolMm) return -1;
  return static_cast<int>(it - grid.begin());
}

std::string Mm(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

// Parameter vector of the physical fit.
enum Param { kF, kC3, kC5, kTiltX, kTiltY, kX0, kY0, kPhi, kTx, kTy, kParams };
const char* const kParamNames[kParams] = {"focal_length_mm", "ftheta_c3",        "ftheta_c5",
                                          "x_axis_tilt_mrad", "y_axis_tilt_mrad",
                                          "x_zero_offset_mrad",
                                          "y_zero_offset_mrad", "plate_rotation_mrad",
                                          "plate_x_mm",        "plate_y_mm"};
// Reported in mrad where the name says so; the solver works in rad.
double Reported(int k, double v) {
  return (k == kTiltX || k == kTiltY || k == kX0 || k == kY0 || k == kPhi) ? v * 1e3 : v;
}

// Residual of one target: R(phi) meas + t - spot(cmd), galvo frame, mm.
struct TargetCost {
  TargetCost(const optics::HeadGeometry& design, const optics::BeamPath& beam,
             const optics::MirrorAngles& angles, const Vector3d& cmd, const Vector2d& meas)
      : design_(design), beam_(beam), angles_(angles), cmd_(cmd), meas_(meas) {}

  template <typename T>
  bool operator()(const T* const p, T* residual) const {
    optics::HeadParamsT<T> h;
    h.focal_length_mm = p[kF];
    h.mirror_separation_mm = T(design_.mirror_separation_mm);
    h.c3 = p[kC3];
    h.c5 = p[kC5];
    h.x_axis_tilt_rad = p[kTiltX];
    h.y_axis_tilt_rad = p[kTiltY];
    h.beam_offset_x_rad = T(beam_.offset_x_mrad * 1e-3);
    h.beam_offset_y_rad = T(beam_.offset_y_mrad * 1e-3);
    h.beam_focal_scale = T(1.0 + beam_.lateral_colour_pct / 100.0);
    h.exit_pupil_height_mm = design_.exit_pupil_height_mm;
    h.pupil_aberration = design_.pupil_aberration;
    h.telecentric = design_.telecentric;
    T xy[2], up[3];
    optics::TraceChiefRay(h, T(angles_.x_rad) + p[kX0], T(angles_.y_rad) + p[kY0], xy, up);
    const T z = T(cmd_.z());
    const T sx = xy[0] + up[0] * z / up[2];
    const T sy = xy[1] + up[1] * z / up[2];
    using std::cos;
    using std::sin;
    const T c = cos(p[kPhi]), s = sin(p[kPhi]);
    residual[0] = c * T(meas_.x()) - s * T(meas_.y()) + p[kTx] - sx;
    residual[1] = s * T(meas_.x()) + c * T(meas_.y()) + p[kTy] - sy;
    return true;
  }

  optics::HeadGeometry design_;
  optics::BeamPath beam_;
  optics::MirrorAngles angles_;
  Vector3d cmd_;
  Vector2d meas_;
};

// Rotation and translation taking `from` onto `to` in the least-squares sense (Umeyama, no
// scale). Dynamic matrices: GCC 12 warns falsely on Eigen's fixed 2 x N path.
Eigen::Isometry2d RigidFit(const std::vector<Vector2d>& from, const std::vector<Vector2d>& to) {
  Eigen::MatrixXd a(2, from.size()), b(2, to.size());
  for (size_t i = 0; i < from.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = from[i];
    b.col(static_cast<Eigen::Index>(i)) = to[i];
  }
  const Eigen::MatrixXd m = Eigen::umeyama(a, b, false);
  Eigen::Isometry2d t = Eigen::Isometry2d::Identity();
  t.linear() = m.topLeftCorner(2, 2);
  t.translation() = m.topRightCorner(2, 1);
  return t;
}

}  // namespace

bool FieldModel::CommandFor(const Vector3d& target, Vector3d* cmd) const {
  const auto map = [&](const Vector2d& c) { return Predict({c.x(), c.y(), target.z()}); };
  Vector2d c = target.head<2>();
  if (!optics::InvertMap2d(map, target.head<2>(), 1e-4, 1e-7, &c)) return false;
  *cmd = Vector3d(c.x(), c.y(), target.z());
  return true;
}

Result<BilinearFieldModel> BilinearFieldModel::Fit(const std::vector<GalvoSample>& nodes) {
  std::vector<double> x, y;
  for (const GalvoSample& s : nodes) {
    x.push_back(s.cmd.x());
    y.push_back(s.cmd.y());
  }
  const std::vector<double> xs = DistinctSorted(x), ys = DistinctSorted(y);
  if (xs.size() < 2 || ys.size() < 2) {
    return InvalidArgument("a bilinear field table needs at least 2 x 2 grid nodes, got " +
                           std::to_string(xs.size()) + " x " + std::to_string(ys.size()));
  }
  const size_t n = xs.size() * ys.size();
  std::vector<Vector2d> error(n, Vector2d::Zero());
  std::vector<int> count(n, 0);
  for (const GalvoSample& s : nodes) {
    const size_t k = static_cast<size_t>(IndexOf(ys, s.cmd.y())) * xs.size() + IndexOf(xs, s.cmd.x());
    error[k] += s.meas - s.cmd.head<2>();
    ++count[k];
  }
  for (size_t k = 0; k < n; ++k) {
    if (count[k] == 0) {
      return InvalidArgument("the field grid has no node at (" + Mm(xs[k % xs.size()]) + ", " +
                             Mm(ys[k / xs.size()]) + ") mm: it must be complete");
    }
    error[k] /= count[k];  // replicates average
  }
  BilinearFieldModel m;
  INSITU_ASSIGN_OR_RETURN(m.error_, optics::GridTable::Make(xs, ys, std::move(error)));
  return m;
}

std::string BilinearFieldModel::name() const {
  return "bilinear " + std::to_string(nx()) + "x" + std::to_string(ny());
}

Vector2d BilinearFieldModel::Predict(const Vector3d& cmd) const {
  return cmd.head<2>() + ErrorAt(cmd.x(), cmd.y());
}

Result<QuadrantFieldModel> QuadrantFieldModel::Fit(const std::vector<GalvoSample>& samples,
                                                   double half_x, double half_y) {
  if (!(half_x > 0 && half_y > 0)) return InvalidArgument("quadrant fit: half sizes must be > 0");
  const auto find = [&](double x, double y, Vector2d* meas) -> Status {
    Vector2d sum = Vector2d::Zero();
    int n = 0;
    for (const GalvoSample& s : samples) {
      if (std::abs(s.cmd.x() - x) < kNodeTolMm && std::abs(s.cmd.y() - y) < kNodeTolMm) {
        sum += s.meas;
        ++n;
      }
    }
    if (n == 0) {
      return InvalidArgument("quadrant fit: no target at (" + Mm(x) + ", " + Mm(y) +
                             ") mm (needs the centre, the four axis ends and the four corners)");
    }
    *meas = sum / n;
    return Status::Ok();
  };
  QuadrantFieldModel m;
  m.half_x_ = half_x;
  m.half_y_ = half_y;
  INSITU_RETURN_IF_ERROR(find(0, 0, &m.centre_));
  const double ax[4][2] = {{half_x, 0}, {-half_x, 0}, {0, half_y}, {0, -half_y}};
  for (int k = 0; k < 4; ++k) {
    Vector2d p;
    INSITU_RETURN_IF_ERROR(find(ax[k][0], ax[k][1], &p));
    m.axis_[k] = p - m.centre_;
  }
  // Quadrants ++, -+, --, +-.
  const double sx[4] = {1, -1, -1, 1}, sy[4] = {1, 1, -1, -1};
  for (int q = 0; q < 4; ++q) {
    const double x = sx[q] * half_x, y = sy[q] * half_y;
    Vector2d p;
    INSITU_RETURN_IF_ERROR(find(x, y, &p));
    m.k_[q] = 0;
    m.kp_[q] = 0;
    const Vector2d lin = m.Predict({x, y, 0});  // with k = 0: the linear part
    const Vector2d r = p - lin;
    m.k_[q] = r.x() / (x * y * y);
    m.kp_[q] = r.y() / (y * x * x);
  }
  return m;
}

Vector2d QuadrantFieldModel::Predict(const Vector3d& cmd) const {
  const double x = cmd.x(), y = cmd.y();
  // Linear per half axis: the axis point's measured offset scaled by x / X (and y / Y).
  const Vector2d ex = x >= 0 ? axis_[0] * (x / half_x_) : axis_[1] * (-x / half_x_);
  const Vector2d ey = y >= 0 ? axis_[2] * (y / half_y_) : axis_[3] * (-y / half_y_);
  const int q = x >= 0 ? (y >= 0 ? 0 : 3) : (y >= 0 ? 1 : 2);
  return centre_ + ex + ey + Vector2d(k_[q] * x * y * y, kp_[q] * y * x * x);
}

Status HeadFitOptions::Validate() const {
  if (max_iterations < 1) return InvalidArgument("max_iterations must be >= 1");
  return Status::Ok();
}

Result<HeadFieldFit> HeadFieldFit::Fit(const std::vector<TargetSample>& samples,
                                       const optics::HeadGeometry& design,
                                       const HeadFitOptions& options,
                                       const optics::BeamPath& beam) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  INSITU_RETURN_IF_ERROR(beam.Validate());
  INSITU_RETURN_IF_ERROR(design.Validate().Prefixed("design"));
  if (samples.size() < 6) {
    return FailedPrecondition("the physical head fit needs at least 6 targets, got " +
                              std::to_string(samples.size()));
  }
  const optics::ScanOptics design_optics(design);
  std::vector<optics::MirrorAngles> angles(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) {
    const Vector3d& c = samples[i].cmd;
    if (!design_optics.Solve(c.x(), c.y(), c.z(), &angles[i])) {
      return InvalidArgument("target commanded at (" + Mm(c.x()) + ", " + Mm(c.y()) +
                             ") mm lies outside the head's design field");
    }
  }
  // Start: the design head, the plate placed by a rigid fit of the measurements onto the
  // commands.
  std::vector<Vector2d> meas, cmd;
  for (const TargetSample& s : samples) {
    meas.push_back(s.meas);
    cmd.push_back(s.cmd.head<2>());
  }
  const Eigen::Isometry2d start = RigidFit(meas, cmd);
  double p[kParams] = {};
  p[kF] = design.focal_length_mm;
  p[kC3] = design.ftheta_c3;
  p[kC5] = design.ftheta_c5;
  p[kTiltX] = design.x_axis_tilt_mrad * 1e-3;
  p[kTiltY] = design.y_axis_tilt_mrad * 1e-3;
  p[kPhi] = std::atan2(start.linear()(1, 0), start.linear()(0, 0));
  p[kTx] = start.translation().x();
  p[kTy] = start.translation().y();

  ceres::Problem problem;
  for (size_t i = 0; i < samples.size(); ++i) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<TargetCost, 2, kParams>(
            new TargetCost(design, beam, angles[i], samples[i].cmd, samples[i].meas)),
        nullptr, p);
  }
  std::vector<int> fixed;
  if (!options.fit_focal_length) fixed.push_back(kF);
  if (!options.fit_ftheta_distortion) {
    fixed.push_back(kC3);
    fixed.push_back(kC5);
  }
  if (!options.fit_axis_tilt) fixed.push_back(kTiltX);
  if (!options.fit_axis_tilt || !options.fit_y_axis_tilt) fixed.push_back(kTiltY);
  if (!options.fit_zero_offsets) {
    fixed.push_back(kX0);
    fixed.push_back(kY0);
  }
  if (!fixed.empty()) problem.SetManifold(p, new ceres::SubsetManifold(kParams, fixed));
  const int free = kParams - static_cast<int>(fixed.size());
  if (2 * static_cast<int>(samples.size()) <= free) {
    return FailedPrecondition("the physical head fit has " + std::to_string(free) +
                              " parameters and only " + std::to_string(2 * samples.size()) +
                              " residuals");
  }
  const ceres::Solver::Options so = PreciseLmOptions(options.max_iterations);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (summary.termination_type != ceres::CONVERGENCE) {
    return FailedPrecondition("the physical head fit did not converge: " + summary.BriefReport());
  }

  HeadFieldFit fit;
  fit.beam_ = beam;
  fit.summary_ = summary.BriefReport();
  fit.head_.design = design;
  fit.head_.built = design;
  fit.head_.built.focal_length_mm = p[kF];
  fit.head_.built.ftheta_c3 = p[kC3];
  fit.head_.built.ftheta_c5 = p[kC5];
  fit.head_.built.x_axis_tilt_mrad = p[kTiltX] * 1e3;
  fit.head_.built.y_axis_tilt_mrad = p[kTiltY] * 1e3;
  fit.head_.x_zero_offset_mrad = p[kX0] * 1e3;
  fit.head_.y_zero_offset_mrad = p[kY0] * 1e3;
  fit.galvo_from_plate_.linear() = Eigen::Rotation2Dd(p[kPhi]).toRotationMatrix();
  fit.galvo_from_plate_.translation() = Vector2d(p[kTx], p[kTy]);

  // Standard errors: sigma^2 (J^T J)^-1 over the free parameters, sigma^2 from the residuals.
  ceres::Problem::EvaluateOptions eo;
  double cost = 0;
  std::vector<double> res;
  ceres::CRSMatrix crs;
  std::vector<double> se(kParams, std::numeric_limits<double>::quiet_NaN());
  fit.rms_mm_ = std::numeric_limits<double>::quiet_NaN();
  if (problem.Evaluate(eo, &cost, &res, nullptr, &crs)) {
    const Eigen::MatrixXd j = DenseJacobian(crs);
    double rss = 0;
    for (double r : res) rss += r * r;
    const int dof = static_cast<int>(res.size()) - free;
    const double sigma2 = dof > 0 ? rss / dof : NAN;
    // The Jacobian's columns are the free parameters in order (the tangent space of the
    // subset manifold).
    const Eigen::MatrixXd jtj = j.leftCols(free).transpose() * j.leftCols(free);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(jtj);
    const double top = eig.eigenvalues().maxCoeff();
    const bool singular = !(eig.eigenvalues().minCoeff() > 1e-12 * top);
    const Eigen::MatrixXd cov = singular ? Eigen::MatrixXd() : Eigen::MatrixXd(jtj.inverse() * sigma2);
    int col = 0;
    for (int k = 0; k < kParams; ++k) {
      if (std::find(fixed.begin(), fixed.end(), k) != fixed.end()) {
        se[k] = 0.0;
        continue;
      }
      se[k] = singular ? std::numeric_limits<double>::quiet_NaN() : std::sqrt(cov(col, col));
      ++col;
    }
    fit.rms_mm_ = std::sqrt(rss / static_cast<double>(samples.size()));
  }
  for (int k = 0; k < kParams; ++k) {
    if (std::find(fixed.begin(), fixed.end(), k) != fixed.end()) continue;
    fit.params_.push_back({kParamNames[k], Reported(k, p[k]), Reported(k, se[k])});
  }
  return fit;
}

Vector2d HeadFieldFit::Predict(const Vector3d& cmd) const {
  Vector3d spot;
  if (!head_.Spot(cmd, beam_, &spot)) return Vector2d(NAN, NAN);
  return spot.head<2>();
}

std::vector<GalvoSample> HeadFieldFit::ToGalvo(const std::vector<TargetSample>& samples) const {
  std::vector<GalvoSample> out;
  out.reserve(samples.size());
  for (const TargetSample& s : samples) out.push_back({s.cmd, galvo_from_plate_ * s.meas});
  return out;
}

Result<PhysicsPlusTableModel> PhysicsPlusTableModel::Fit(const HeadFieldFit& physics,
                                                         const std::vector<GalvoSample>& nodes) {
  // The table holds meas - physics(cmd) at the nodes: a bilinear model of cmd -> cmd + that.
  std::vector<GalvoSample> left;
  for (const GalvoSample& s : nodes) {
    left.push_back({s.cmd, s.cmd.head<2>() + (s.meas - physics.Predict(s.cmd))});
  }
  INSITU_ASSIGN_OR_RETURN(BilinearFieldModel table, BilinearFieldModel::Fit(left));
  PhysicsPlusTableModel m;
  m.physics_ = physics;
  m.residual_ = std::move(table);
  return m;
}

Vector2d PhysicsPlusTableModel::Predict(const Vector3d& cmd) const {
  return physics_.Predict(cmd) + residual_.ErrorAt(cmd.x(), cmd.y());
}

namespace {

// Residual of one spot of a second beam: spot(cmd; path) - meas, galvo frame, mm.
struct BeamCost {
  BeamCost(const optics::HeadGeometry& built, const optics::MirrorAngles& angles,
           const Vector3d& cmd, const Vector2d& meas)
      : built_(built), angles_(angles), cmd_(cmd), meas_(meas) {}

  template <typename T>
  bool operator()(const T* const p, T* residual) const {
    optics::HeadParamsT<T> h;
    h.focal_length_mm = T(built_.focal_length_mm);
    h.mirror_separation_mm = p[3];
    h.c3 = T(built_.ftheta_c3);
    h.c5 = T(built_.ftheta_c5);
    h.x_axis_tilt_rad = T(built_.x_axis_tilt_mrad * 1e-3);
    h.y_axis_tilt_rad = T(built_.y_axis_tilt_mrad * 1e-3);
    h.beam_offset_x_rad = p[0];
    h.beam_offset_y_rad = p[1];
    h.beam_focal_scale = T(1) + p[2];
    h.exit_pupil_height_mm = built_.exit_pupil_height_mm;
    h.pupil_aberration = built_.pupil_aberration;
    h.telecentric = built_.telecentric;
    T xy[2], up[3];
    optics::TraceChiefRay(h, T(angles_.x_rad), T(angles_.y_rad), xy, up);
    const T z = T(cmd_.z());
    residual[0] = xy[0] + up[0] * z / up[2] - T(meas_.x());
    residual[1] = xy[1] + up[1] * z / up[2] - T(meas_.y());
    return true;
  }

  optics::HeadGeometry built_;
  optics::MirrorAngles angles_;
  Vector3d cmd_;
  Vector2d meas_;
};

}  // namespace

Result<BeamPathFit> FitBeamPath(const optics::HeadModel& head,
                                const std::vector<GalvoSample>& spots, bool fit_mirror_separation) {
  if (spots.size() < 4) {
    return FailedPrecondition("the beam path fit needs at least 4 spots, got " +
                              std::to_string(spots.size()));
  }
  if (fit_mirror_separation) {
    double z_lo = 1e300, z_hi = -1e300;
    for (const GalvoSample& s : spots) {
      z_lo = std::min(z_lo, s.cmd.z());
      z_hi = std::max(z_hi, s.cmd.z());
    }
    // The separation tilts the chief rays only: spots on one plane cannot see it.
    if (!(z_hi - z_lo >= 2.0)) {
      return FailedPrecondition("the mirror separation needs spots at two heights at least 2 mm "
                                "apart; these span " + Mm(z_hi - z_lo) + " mm");
    }
  }
  // offset x, y (rad), focal scale - 1, mirror separation (mm)
  double p[4] = {0, 0, 0, head.built.mirror_separation_mm};
  ceres::Problem problem;
  for (const GalvoSample& s : spots) {
    optics::MirrorAngles a;
    if (!head.CommandAngles(s.cmd, &a)) {
      return InvalidArgument("spot commanded at (" + Mm(s.cmd.x()) + ", " + Mm(s.cmd.y()) +
                             ") mm lies outside the head's design field");
    }
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<BeamCost, 2, 4>(
                                 new BeamCost(head.built, a, s.cmd, s.meas)),
                             nullptr, p);
  }
  const int free = fit_mirror_separation ? 4 : 3;
  if (!fit_mirror_separation) problem.SetManifold(p, new ceres::SubsetManifold(4, {3}));
  const ceres::Solver::Options so = PreciseLmOptions(50);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (summary.termination_type != ceres::CONVERGENCE) {
    return FailedPrecondition("the beam path fit did not converge: " + summary.BriefReport());
  }
  BeamPathFit fit;
  fit.path = {p[0] * 1e3, p[1] * 1e3, p[2] * 1e2};
  fit.mirror_separation_mm = p[3];
  double cost = 0;
  std::vector<double> res;
  ceres::CRSMatrix crs;
  if (problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, &res, nullptr, &crs)) {
    const Eigen::MatrixXd j = DenseJacobian(crs);
    double rss = 0;
    for (double r : res) rss += r * r;
    fit.rms_mm = std::sqrt(rss / spots.size());
    const int dof = static_cast<int>(res.size()) - free;
    const Eigen::MatrixXd jtj = j.transpose() * j;  // over the free parameters, in order
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(jtj);
    if (dof > 0 && eig.eigenvalues().minCoeff() > 1e-12 * eig.eigenvalues().maxCoeff()) {
      const Eigen::MatrixXd cov = jtj.inverse() * (rss / dof);
      fit.stderr_offset_x_mrad = std::sqrt(cov(0, 0)) * 1e3;
      fit.stderr_offset_y_mrad = std::sqrt(cov(1, 1)) * 1e3;
      fit.stderr_lateral_colour_pct = std::sqrt(cov(2, 2)) * 1e2;
      if (fit_mirror_separation) fit.stderr_mirror_separation_mm = std::sqrt(cov(3, 3));
    } else {
      fit.stderr_offset_x_mrad = fit.stderr_offset_y_mrad = fit.stderr_lateral_colour_pct =
          fit.stderr_mirror_separation_mm = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return fit;
}

ModelError PredictionError(const FieldModel& model, const std::vector<GalvoSample>& samples) {
  ModelError e;
  double ss = 0;
  for (const GalvoSample& s : samples) {
    const double d = (s.meas - model.Predict(s.cmd)).norm();
    ss += d * d;
    e.max_mm = std::max(e.max_mm, d);
  }
  e.rms_mm = samples.empty() ? 0.0 : std::sqrt(ss / samples.size());
  return e;
}

ModelError NominalError(const std::vector<GalvoSample>& samples) {
  ModelError e;
  double ss = 0;
  for (const GalvoSample& s : samples) {
    const double d = (s.meas - s.cmd.head<2>()).norm();
    ss += d * d;
    e.max_mm = std::max(e.max_mm, d);
  }
  e.rms_mm = samples.empty() ? 0.0 : std::sqrt(ss / samples.size());
  return e;
}

}  // namespace insitu::fit
