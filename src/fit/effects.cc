#include "insitu/fit/effects.h"

#include <Eigen/Dense>
#include <cassert>
#include <cmath>

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
  void Apply(const FieldPoint& p, const double* q, Vector2d* uv) const override {
    const Vector2d d(p.cmd.x() - q[1], p.cmd.y() - q[2]);
    *uv += q[0] * d.squaredNorm() * d;
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

}  // namespace

std::vector<std::unique_ptr<Effect>> EffectLibrary() {
  std::vector<std::unique_ptr<Effect>> lib;
  lib.push_back(std::make_unique<Offset>());
  lib.push_back(std::make_unique<Scale>());
  lib.push_back(std::make_unique<Rotation>());
  lib.push_back(std::make_unique<Skew>());
  lib.push_back(std::make_unique<MirrorSeparation>());
  lib.push_back(std::make_unique<LensRadial>());
  lib.push_back(std::make_unique<Perspective>());
  lib.push_back(std::make_unique<ThermalDrift>());
  lib.push_back(std::make_unique<TrackingLag>());
  lib.push_back(std::make_unique<FocusScale>());
  return lib;
}

std::unique_ptr<Effect> MakeEffect(const std::string& name) {
  for (std::unique_ptr<Effect>& e : EffectLibrary()) {
    if (e->name() == name) return std::move(e);
  }
  return nullptr;
}

}  // namespace insitu::fit
