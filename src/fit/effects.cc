#include "insitu/fit/effects.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

#include "insitu/optics/scan_head.h"

namespace insitu::fit {
namespace {

using Eigen::Vector2d;

// Regressors of one point: column j is how the point's (u, v) moves per unit of parameter j
// (to first order about zero).
using Regressors = Eigen::Matrix<double, 2, Eigen::Dynamic>;

// Linear least squares of the residual (x and y components stacked) on `k` regressor columns
// plus a free offset per axis. The offsets stand in for the shift an unmodelled or not yet
// fitted offset leaves in the residual (the commanded origin of a data set need not be the
// optical axis), so they do not leak into the effect's starting values. Minimum-norm solution
// when the columns are dependent (a column absent in the data gives 0).
template <typename RowsFn>
std::vector<double> LinearStart(const FieldData& data, const std::vector<Vector2d>& residual, int k,
                                RowsFn rows) {
  assert(residual.size() == data.points.size());
  const int n = static_cast<int>(data.points.size());
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(2 * n, k + 2);
  Eigen::VectorXd b(2 * n);
  Regressors r(2, k);
  for (int i = 0; i < n; ++i) {
    r.setZero();
    rows(data.points[i], residual[i], &r);
    a.block(2 * i, 0, 2, k) = r;
    a(2 * i, k) = 1.0;
    a(2 * i + 1, k + 1) = 1.0;
    b.segment<2>(2 * i) = residual[i];
  }
  std::vector<double> out(k, 0.0);
  if (n == 0) return out;
  const Eigen::VectorXd sol = a.completeOrthogonalDecomposition().solve(b);
  for (int j = 0; j < k; ++j) out[j] = std::isfinite(sol(j)) ? sol(j) : 0.0;
  return out;
}

// Where an effect's optical axis (a centre x0, y0) may lie: within the field the commands
// span, taken symmetric about the command origin (a galvo's command 0 is the middle of its
// range, so a data set measured on one side of it, like seed 001's moves along +x and +y,
// still belongs to a field around it). The axis of a measured field lies inside it; where the
// data do not pin it, the cost falls towards a limit at infinity instead (mirror_separation on
// points along the axes only: kappa -> 0 and x0 -> inf with kappa x0 fixed reproduce a y^2 bow,
// a term with no physical reason), and a free fit would follow it.
void CentreBounds(const FieldData& data, int x0_index, std::vector<double>* lo,
                  std::vector<double>* hi) {
  if (data.points.empty()) return;
  Vector2d a = data.points[0].cmd, b = a;
  for (const FieldPoint& p : data.points) {
    a = a.cwiseMin(p.cmd);
    b = b.cwiseMax(p.cmd);
  }
  // A field of one line (every x the same) still leaves its centre some room: 1 mm.
  (*lo)[x0_index] = std::min({a.x(), -b.x(), -1.0});
  (*hi)[x0_index] = std::max({b.x(), -a.x(), 1.0});
  (*lo)[x0_index + 1] = std::min({a.y(), -b.y(), -1.0});
  (*hi)[x0_index + 1] = std::max({b.y(), -a.y(), 1.0});
}

Vector2d Centroid(const FieldData& data) {
  Vector2d c = Vector2d::Zero();
  for (const FieldPoint& p : data.points) c += p.cmd;
  return data.points.empty() ? c : Vector2d(c / static_cast<double>(data.points.size()));
}

class Offset : public Effect {
 public:
  std::string name() const override { return "offset"; }
  std::vector<std::string> param_names() const override { return {"dx", "dy"}; }
  std::string meaning() const override {
    return "constant shift of the field: galvo zero offsets (scan head) or the head mounted off "
           "the measuring frame's origin (set-up)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    Vector2d m = Vector2d::Zero();
    for (const Vector2d& r : residual) m += r;
    if (!data.points.empty()) m /= static_cast<double>(data.points.size());
    return {m.x(), m.y()};
  }
  void Apply(const FieldPoint&, const double* q, Vector2d* uv) const override {
    uv->x() += q[0];
    uv->y() += q[1];
  }
};

class Scale : public Effect {
 public:
  std::string name() const override { return "scale"; }
  std::vector<std::string> param_names() const override { return {"sx", "sy"}; }
  std::string meaning() const override {
    return "relative field size error per axis: galvo gain or f-theta focal length (scan head), "
           "or the measuring scale (set-up)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 2, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
      (*r)(0, 0) = p.cmd.x();
      (*r)(1, 1) = p.cmd.y();
    });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    uv->x() += q[0] * p.cmd.x();
    uv->y() += q[1] * p.cmd.y();
  }
};

class Rotation : public Effect {
 public:
  std::string name() const override { return "rotation"; }
  std::vector<std::string> param_names() const override { return {"theta"}; }
  std::string meaning() const override {
    return "field rotated about the origin: the head mounted rotated against the measuring frame "
           "(set-up) or a galvo turned in its mount (scan head)";
  }
  int stage() const override { return 1; }
  // The antisymmetric part of the residual about the modelled position (meas - residual):
  // a small rotation moves (u, v) by theta (-v, u).
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 1,
                       [](const FieldPoint& p, const Vector2d& res, Regressors* r) {
                         const Vector2d model = p.meas - res;
                         (*r)(0, 0) = -model.y();
                         (*r)(1, 0) = model.x();
                       });
  }
  void Apply(const FieldPoint&, const double* q, Vector2d* uv) const override {
    // A fit applies one angle to every point many times over: sin/cos of it once.
    thread_local double angle = 0.0, c = 1.0, s = 0.0;
    if (q[0] != angle) {
      angle = q[0];
      c = std::cos(angle);
      s = std::sin(angle);
    }
    *uv = Vector2d(c * uv->x() - s * uv->y(), s * uv->x() + c * uv->y());
  }
};

class Skew : public Effect {
 public:
  std::string name() const override { return "skew"; }
  std::vector<std::string> param_names() const override { return {"gamma"}; }
  std::string meaning() const override {
    return "deflection axes not orthogonal: the mirror shafts not at right angles (scan head)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 1, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
      (*r)(0, 0) = p.cmd.y();
    });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    uv->x() += q[0] * p.cmd.y();
  }
};

// Centre parameters start at the centroid of the commanded points: the optical axis is near
// the middle of a measured field, not necessarily at the commanded origin.
class MirrorSeparation : public Effect {
 public:
  std::string name() const override { return "mirror_separation"; }
  std::vector<std::string> param_names() const override { return {"kappa", "x0", "y0"}; }
  std::string meaning() const override {
    return "two-mirror pincushion: the first mirror deflects before the second, so x grows with "
           "y^2 (scan head; seeds 001, 003)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    const Vector2d c = Centroid(data);
    const std::vector<double> k =
        LinearStart(data, residual, 1, [&c](const FieldPoint& p, const Vector2d&, Regressors* r) {
          const Vector2d d = p.cmd - c;
          (*r)(0, 0) = d.x() * d.y() * d.y();
        });
    return {k[0], c.x(), c.y()};
  }
  void Bounds(const FieldData& data, std::vector<double>* lo,
              std::vector<double>* hi) const override {
    CentreBounds(data, 1, lo, hi);
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    const double dy = p.cmd.y() - q[2];
    uv->x() += q[0] * (p.cmd.x() - q[1]) * dy * dy;
  }
};

class LensRadial : public Effect {
 public:
  std::string name() const override { return "lens_radial"; }
  std::vector<std::string> param_names() const override { return {"k", "x0", "y0"}; }
  std::string meaning() const override {
    return "radial distortion of the f-theta lens about its axis: pincushion k > 0, barrel k < 0 "
           "(scan head)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    const Vector2d c = Centroid(data);
    const std::vector<double> k =
        LinearStart(data, residual, 1, [&c](const FieldPoint& p, const Vector2d&, Regressors* r) {
          const Vector2d d = p.cmd - c;
          r->col(0) = d.squaredNorm() * d;
        });
    return {k[0], c.x(), c.y()};
  }
  void Bounds(const FieldData& data, std::vector<double>* lo,
              std::vector<double>* hi) const override {
    CentreBounds(data, 1, lo, hi);
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    const Vector2d d(p.cmd.x() - q[1], p.cmd.y() - q[2]);
    *uv += q[0] * d.squaredNorm() * d;
  }
};

// mirror_separation and lens_radial about one optical axis: in a head they are not two
// centres but one, where the objective's axis meets the field.
class HeadDistortion : public Effect {
 public:
  std::string name() const override { return "head_distortion"; }
  std::vector<std::string> param_names() const override { return {"kappa", "k", "x0", "y0"}; }
  std::string meaning() const override {
    return "the head's leading-order distortion about its optical axis: the two-mirror "
           "pincushion (x grows with y^2) and the objective's radial term, both about the one "
           "axis (x0, y0) (scan head; seeds 001, 003)";
  }
  int stage() const override { return 0; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    const Vector2d c = Centroid(data);
    const std::vector<double> k =
        LinearStart(data, residual, 2, [&c](const FieldPoint& p, const Vector2d&, Regressors* r) {
          const Vector2d d = p.cmd - c;
          (*r)(0, 0) = d.x() * d.y() * d.y();
          r->col(1) = d.squaredNorm() * d;
        });
    return {k[0], k[1], c.x(), c.y()};
  }
  void Bounds(const FieldData& data, std::vector<double>* lo,
              std::vector<double>* hi) const override {
    CentreBounds(data, 2, lo, hi);
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    const Vector2d d(p.cmd.x() - q[2], p.cmd.y() - q[3]);
    uv->x() += q[0] * d.x() * d.y() * d.y();
    *uv += q[1] * d.squaredNorm() * d;
  }
};

class Perspective : public Effect {
 public:
  std::string name() const override { return "perspective"; }
  std::vector<std::string> param_names() const override { return {"p", "q"}; }
  std::string meaning() const override {
    return "keystone: the measuring camera's image plane not parallel to the field (set-up)";
  }
  int stage() const override { return 2; }
  // To first order (u, v) / w = (u, v) (1 - p x - q y).
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 2,
                       [](const FieldPoint& p, const Vector2d& res, Regressors* r) {
                         const Vector2d model = p.meas - res;
                         r->col(0) = -p.cmd.x() * model;
                         r->col(1) = -p.cmd.y() * model;
                       });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    *uv /= 1.0 + q[0] * p.cmd.x() + q[1] * p.cmd.y();
  }
};

class ThermalDrift : public Effect {
 public:
  std::string name() const override { return "thermal_drift"; }
  std::vector<std::string> param_names() const override { return {"ox", "oy", "g"}; }
  std::string meaning() const override {
    return "galvo offset (mm/s) and gain (1/s) drifting linearly in time as the head warms up "
           "(scan head)";
  }
  int stage() const override { return 0; }
  bool Applicable(const FieldData& data) const override { return data.has_t; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 3, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
      (*r)(0, 0) = p.t_s;
      (*r)(1, 1) = p.t_s;
      r->col(2) = p.t_s * p.cmd;
    });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    uv->x() += p.t_s * (q[0] + q[2] * p.cmd.x());
    uv->y() += p.t_s * (q[1] + q[2] * p.cmd.y());
  }
};

class TrackingLag : public Effect {
 public:
  std::string name() const override { return "tracking_lag"; }
  std::vector<std::string> param_names() const override { return {"tau"}; }
  std::string meaning() const override {
    return "the spot trails the command by the servo tracking delay tau (s) when measured on the "
           "move (scan head)";
  }
  int stage() const override { return 0; }
  bool Applicable(const FieldData& data) const override { return data.has_v; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 1, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
      r->col(0) = -p.v_mm_s;
    });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    *uv -= q[0] * p.v_mm_s;
  }
};

class FocusScale : public Effect {
 public:
  std::string name() const override { return "focus_scale"; }
  std::vector<std::string> param_names() const override { return {"c"}; }
  std::string meaning() const override {
    return "field scale changing with the focus shift z (1/mm): the z-shifter changes the "
           "effective focal length (scan head)";
  }
  int stage() const override { return 0; }
  bool Applicable(const FieldData& data) const override { return data.has_z; }
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    return LinearStart(data, residual, 1, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
      r->col(0) = p.z_cmd_mm * p.cmd;
    });
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    *uv += q[0] * p.z_cmd_mm * p.cmd;
  }
};

// The exact two-mirror f-theta head (optics/scan_head.h, the simulator's own optics) driven
// linearly, as a board without a correction table drives it: optical angles
//   a = (1 + gx) x / f + x0,   b = (1 + gy) y / f + y0
// traced through both mirrors (the X mirror first, each axis tilted toward its incoming beam)
// and an objective r = f theta (1 + c3 theta^2 + c5 theta^4), to the plane z = z_cmd_mm. The
// effect is where that head puts the spot minus the command:
// - a small command lands where it asks, so f does not scale the field; it sets the size of
//   the two-mirror distortion: X pincushion, Y barrel, ~ x y^2 / (2 f^2) (mirror_separation's
//   leading term);
// - c3, c5 the lens's radial distortion (lens_radial's, k = c3 / f^2);
// - x0, y0 the mirrors' zero offsets: a shift of f x0 and the distortion centred off the
//   command origin (offset's physical form);
// - the tilts: a shear that grows with the field (skew's);
// - the gains gx, gy scale the field in angle (scale's): a scale applied after the head would
//   misplace a 2 mm distortion by 3 x 0.4 % of it, 24 um, at the corner of a 110 mm field;
// - the mirror separation e moves the chief ray's pupil, not its focal point: it shows only in
//   points off the focal plane (z_cmd_mm), with the exit pupil at 1.22 f above it (the default
//   head's proportion, 310 mm for 255).
// So the effect holds the leading-order head effects at once; the diagnosis tries it in their
// place once they have shown the head is there (fit/diagnose.h), never on a field that is only
// linear.
class HeadGeometryEffect : public Effect {
 public:
  enum { kF, kE, kX0, kY0, kTx, kTy, kC3, kC5, kGx, kGy, kCount };
  std::string name() const override { return "head_geometry"; }
  std::vector<std::string> param_names() const override {
    return {"f_mm", "e_mm", "x0_mrad", "y0_mrad", "tx_mrad", "ty_mrad", "c3", "c5", "gx", "gy"};
  }
  std::string meaning() const override {
    return "the exact two-mirror f-theta head: focal length f (the two-mirror distortion's "
           "size), mirror separation e, zero offsets, mirror-axis tilts, lens distortion c3, c5, "
           "galvo gains (scan head; the simulator's optics)";
  }
  int stage() const override { return 0; }

  // f from a scan of field angles: for each f the two-mirror distortion it gives, plus the
  // radial term k |c|^2 c, a scale per axis and a free offset fitted linearly to the residual;
  // the f that leaves least starts the fit, with c3 = k f^2 and the scales as gains. Zero
  // offsets and tilts start at 0, e at 0.063 f (the default head's 16 mm for 255).
  std::vector<double> Initial(const FieldData& data,
                              const std::vector<Vector2d>& residual) const override {
    const double half = HalfField(data);
    std::vector<double> q(kCount, 0.0);
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i <= 40; ++i) {
      const double angle = kWidest * std::pow(kNarrowest / kWidest, i / 40.0);
      std::vector<double> t(kCount, 0.0);
      t[kF] = half / angle;
      t[kE] = 0.063 * t[kF];
      std::vector<Vector2d> rest(residual.size());
      for (size_t j = 0; j < residual.size(); ++j) {
        Vector2d uv = data.points[j].cmd;
        Apply(data.points[j], t.data(), &uv);
        rest[j] = residual[j] - (uv - data.points[j].cmd);
      }
      const std::vector<double> k =
          LinearStart(data, rest, 3, [](const FieldPoint& p, const Vector2d&, Regressors* r) {
            r->col(0) = p.cmd.squaredNorm() * p.cmd;
            (*r)(0, 1) = p.cmd.x();
            (*r)(1, 2) = p.cmd.y();
          });
      t[kC3] = std::clamp(k[0] * t[kF] * t[kF], -kMaxC3, kMaxC3);
      t[kGx] = std::clamp(k[1], -0.5, 1.0);
      t[kGy] = std::clamp(k[2], -0.5, 1.0);
      double ss = 0.0;
      Vector2d mean = Vector2d::Zero();
      for (size_t j = 0; j < rest.size(); ++j) {
        const Vector2d& c = data.points[j].cmd;
        rest[j] -= (t[kC3] / (t[kF] * t[kF])) * c.squaredNorm() * c +
                   Vector2d(t[kGx] * c.x(), t[kGy] * c.y());
        mean += rest[j];
      }
      // What is left about its mean (the free offset): the f that leaves least starts.
      if (!rest.empty()) mean /= static_cast<double>(rest.size());
      for (const Vector2d& r : rest) ss += (r - mean).squaredNorm();
      if (ss < best) {
        best = ss;
        q = t;
      }
    }
    return q;
  }
  void Bounds(const FieldData& data, std::vector<double>* lo,
              std::vector<double>* hi) const override {
    const double half = HalfField(data);
    (*lo)[kF] = half / kWidest;
    (*hi)[kF] = half / kNarrowest;
    (*lo)[kE] = 0.0;
    (*hi)[kE] = 1e4;
    for (int k : {kX0, kY0}) {
      (*lo)[k] = -100.0;  // mrad: +-5.7 deg of zero error is a broken head, not an offset
      (*hi)[k] = 100.0;
    }
    for (int k : {kTx, kTy}) {
      (*lo)[k] = -10.0;  // mrad: galvo mounts hold 0.5-2 (docs/simulator.md)
      (*hi)[k] = 10.0;
    }
    for (int k : {kGx, kGy}) {
      (*lo)[k] = -0.5;
      (*hi)[k] = 1.0;
    }
    (*lo)[kC3] = -kMaxC3;
    (*hi)[kC3] = kMaxC3;
    (*lo)[kC5] = -5.0;
    (*hi)[kC5] = 5.0;
  }
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    *uv += Spot(q, p.cmd, p.z_cmd_mm) - p.cmd;
  }

 private:
  // Where the head puts the spot of command c on the plane z.
  static Vector2d Spot(const double* q, const Vector2d& c, double z_mm) {
    optics::HeadParamsT<double> h;
    h.focal_length_mm = q[kF];
    h.mirror_separation_mm = q[kE];
    h.c3 = q[kC3];
    h.c5 = q[kC5];
    h.x_axis_tilt_rad = q[kTx] * 1e-3;
    h.y_axis_tilt_rad = q[kTy] * 1e-3;
    h.beam_offset_x_rad = 0.0;
    h.beam_offset_y_rad = 0.0;
    h.beam_focal_scale = 1.0;
    h.exit_pupil_height_mm = kPupilPerFocal * q[kF];
    h.pupil_aberration = 0.0;
    const double a = (1.0 + q[kGx]) * c.x() / q[kF] + q[kX0] * 1e-3;
    const double b = (1.0 + q[kGy]) * c.y() / q[kF] + q[kY0] * 1e-3;
    double xy[2], up[3];
    optics::TraceChiefRay(h, a, b, xy, up);
    Vector2d spot(xy[0], xy[1]);
    if (z_mm != 0.0) spot += Vector2d(up[0], up[1]) * (z_mm / up[2]);
    return spot;
  }
  // The focal length's range as half field angles: the widest f-theta lenses reach ~0.45 rad;
  // at 0.002 rad the two-mirror distortion is below 1e-6 of the field.
  static constexpr double kWidest = 0.7, kNarrowest = 0.002;
  static constexpr double kMaxC3 = 0.5;  // catalogue f-theta lenses: |c3| < ~0.1
  static constexpr double kPupilPerFocal = 310.0 / 255.0;
  // The field's half width about the command origin (the optical axis of a linear drive).
  static double HalfField(const FieldData& data) {
    double half = 0.0;
    for (const FieldPoint& p : data.points) half = std::max(half, p.cmd.cwiseAbs().maxCoeff());
    return half > 0.0 ? half : 1.0;
  }
};

}  // namespace

std::vector<std::unique_ptr<Effect>> EffectLibrary() {
  std::vector<std::unique_ptr<Effect>> lib;
  lib.push_back(std::make_unique<Offset>());
  lib.push_back(std::make_unique<Scale>());
  lib.push_back(std::make_unique<Rotation>());
  lib.push_back(std::make_unique<Skew>());
  lib.push_back(std::make_unique<MirrorSeparation>());
  lib.push_back(std::make_unique<LensRadial>());
  lib.push_back(std::make_unique<HeadGeometryEffect>());
  lib.push_back(std::make_unique<Perspective>());
  lib.push_back(std::make_unique<ThermalDrift>());
  lib.push_back(std::make_unique<TrackingLag>());
  lib.push_back(std::make_unique<FocusScale>());
  lib.push_back(std::make_unique<HeadDistortion>());
  return lib;
}

std::unique_ptr<Effect> MakeEffect(const std::string& name) {
  for (std::unique_ptr<Effect>& e : EffectLibrary()) {
    if (e->name() == name) return std::move(e);
  }
  return nullptr;
}

}  // namespace insitu::fit
