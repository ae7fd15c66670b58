#include "insitu/fit/model_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numeric>

#include "fit/ceres_support.h"

namespace insitu::fit {
namespace {

using Eigen::Vector2d;

// The effects of a model in the order they act (stage, then as listed), with the offset of
// each one's parameters in the concatenated parameter vector.
struct Chain {
  std::vector<const Effect*> effects;
  std::vector<int> given;  // effects[k] is the given effect given[k]
  std::vector<int> begin;  // parameters of effects[k]: theta[begin[k] .. begin[k + 1])
  // For an additive effect k (stage 0): the first later effect that is not additive (or
  // size()). The additive effects between add amounts that do not depend on the position, so
  // a change of effect k passes through them unchanged. Else k + 1.
  std::vector<int> skip_to;

  explicit Chain(const std::vector<const Effect*>& list) {
    given.resize(list.size());
    std::iota(given.begin(), given.end(), 0);
    std::stable_sort(given.begin(), given.end(),
                     [&list](int a, int b) { return list[a]->stage() < list[b]->stage(); });
    begin.push_back(0);
    for (int g : given) {
      effects.push_back(list[g]);
      begin.push_back(begin.back() + static_cast<int>(list[g]->param_names().size()));
    }
    for (int k = 0; k < size(); ++k) {
      int next = k + 1;
      if (effects[k]->stage() == 0) {
        while (next < size() && effects[next]->stage() == 0) ++next;
      }
      skip_to.push_back(next);
    }
  }
  int size() const { return static_cast<int>(effects.size()); }
  int parameters() const { return begin.back(); }
  // Applies effects first.. of the chain to `uv` (the state before effect `first`).
  void ApplyFrom(int first, const FieldPoint& p, const double* theta, Vector2d* uv) const {
    for (int k = first; k < size(); ++k) effects[k]->Apply(p, theta + begin[k], uv);
  }
};

// Ceres works on z with theta = scale * z, where scale[j] makes a unit of z move the modelled
// points by about 1 mm rms at the start. The parameters differ by ten orders of magnitude in
// their own units (a centre ~10 mm, kappa ~1e-6 /mm^2); in z the Jacobian columns are of one
// size, Ceres's relative parameter tolerance compares like with like and one difference step
// suits every parameter.
constexpr double kStepZ = 1e-5;  // mm of movement: model rounding ~1e-14 mm -> ~1e-9 relative

// All points in one residual block (2 residuals per point: meas - model in x, y), one parameter
// block per effect of the chain. The Jacobian is by central differences, done here rather than
// by NumericDiffCostFunction so that a perturbation of effect k starts from the state before k
// (the earlier effects are not applied again, the later additive ones neither) and the step is
// in the normalised z. One block rather than one per point: a 2n x p dense Jacobian, no
// per-block bookkeeping in Ceres.
class FieldCost : public ceres::CostFunction {
 public:
  FieldCost(const FieldData& data, const Chain& chain, std::vector<double> scale)
      : data_(data), chain_(chain), scale_(std::move(scale)) {
    set_num_residuals(2 * static_cast<int>(data.points.size()));
    for (int k = 0; k < chain.size(); ++k) {
      mutable_parameter_block_sizes()->push_back(chain.begin[k + 1] - chain.begin[k]);
    }
  }

  bool Evaluate(double const* const* z, double* residuals, double** jacobians) const override {
    const int n = static_cast<int>(data_.points.size());
    const int m = chain_.size();
    std::vector<double> theta(chain_.parameters());
    for (int k = 0; k < m; ++k) {
      for (int j = chain_.begin[k]; j < chain_.begin[k + 1]; ++j) {
        theta[j] = scale_[j] * z[k][j - chain_.begin[k]];
      }
    }
    // state[i * (m + 1) + k]: point i before effect k (k = m: the model).
    std::vector<Vector2d> state(static_cast<size_t>(n) * (m + 1));
    for (int i = 0; i < n; ++i) {
      const FieldPoint& p = data_.points[i];
      Vector2d* s = &state[static_cast<size_t>(i) * (m + 1)];
      s[0] = p.cmd;
      for (int k = 0; k < m; ++k) {
        s[k + 1] = s[k];
        chain_.effects[k]->Apply(p, theta.data() + chain_.begin[k], &s[k + 1]);
      }
      const Vector2d r = p.meas - s[m];
      residuals[2 * i] = r.x();
      residuals[2 * i + 1] = r.y();
    }
    for (int i = 0; i < 2 * n; ++i) {
      if (!std::isfinite(residuals[i])) return false;
    }
    if (jacobians == nullptr) return true;
    for (int k = 0; k < m; ++k) {
      if (jacobians[k] == nullptr) continue;
      const int size = chain_.begin[k + 1] - chain_.begin[k];
      for (int jj = 0; jj < size; ++jj) {
        const int j = chain_.begin[k] + jj;
        const double t0 = theta[j];
        const double h = scale_[j] * kStepZ;
        std::vector<double> moved = theta;
        // All points at +h, then all at -h: an effect that caches per parameter value (the
        // rotation's sin and cos) sees one value at a time.
        for (int sign = 1; sign >= -1; sign -= 2) {
          moved[j] = t0 + sign * h;
          for (int i = 0; i < n; ++i) {
            const FieldPoint& p = data_.points[i];
            const Vector2d* s = &state[static_cast<size_t>(i) * (m + 1)];
            Vector2d uv = s[k];
            chain_.effects[k]->Apply(p, moved.data() + chain_.begin[k], &uv);
            const int next = chain_.skip_to[k];
            if (next > k + 1) uv = s[next] + (uv - s[k + 1]);
            chain_.ApplyFrom(next, p, moved.data(), &uv);
            // d(meas - model)/dz by central differences
            const Vector2d d = -sign * (uv - s[m]) / (2.0 * kStepZ);
            double* row = jacobians[k] + 2 * i * size + jj;
            if (sign == 1) {
              row[0] = d.x();
              row[size] = d.y();
            } else {
              row[0] += d.x();
              row[size] += d.y();
            }
          }
        }
      }
    }
    return true;
  }

 private:
  const FieldData& data_;
  const Chain& chain_;
  std::vector<double> scale_;
};

// Each effect's physical bounds (Effect::Bounds) on its block of z (theta = scale z, scale > 0).
void BoundParameters(const FieldData& data, const Chain& chain, const std::vector<double>& scale,
                     std::vector<std::vector<double>>* z, ceres::Problem* problem) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (int k = 0; k < chain.size(); ++k) {
    const int size = chain.begin[k + 1] - chain.begin[k];
    std::vector<double> lo(size, -kInf), hi(size, kInf);
    chain.effects[k]->Bounds(data, &lo, &hi);
    for (int jj = 0; jj < size; ++jj) {
      const double s = scale[chain.begin[k] + jj];
      if (std::isfinite(lo[jj])) problem->SetParameterLowerBound((*z)[k].data(), jj, lo[jj] / s);
      if (std::isfinite(hi[jj])) problem->SetParameterUpperBound((*z)[k].data(), jj, hi[jj] / s);
    }
  }
}

void Model(const FieldData& data, const Chain& chain, const std::vector<double>& theta,
           std::vector<Vector2d>* model) {
  model->resize(data.points.size());
  for (size_t i = 0; i < data.points.size(); ++i) {
    (*model)[i] = data.points[i].cmd;
    chain.ApplyFrom(0, data.points[i], theta.data(), &(*model)[i]);
  }
}

// Starting values: each effect in chain order from the residual the effects before it leave.
std::vector<double> InitialTheta(const FieldData& data, const Chain& chain,
                                 const std::vector<std::vector<double>>& start) {
  std::vector<double> theta(chain.parameters(), 0.0);
  std::vector<Vector2d> residual(data.points.size());
  for (int k = 0; k < chain.size(); ++k) {
    const size_t given = static_cast<size_t>(chain.given[k]);
    const int size = chain.begin[k + 1] - chain.begin[k];
    std::vector<double> init;
    if (given < start.size() && static_cast<int>(start[given].size()) == size) {
      init = start[given];
    } else {
      // The effects before k only: zero parameters need not mean "no effect" (head_geometry's
      // focal length).
      for (size_t i = 0; i < data.points.size(); ++i) {
        Vector2d uv = data.points[i].cmd;
        for (int e = 0; e < k; ++e) {
          chain.effects[e]->Apply(data.points[i], theta.data() + chain.begin[e], &uv);
        }
        residual[i] = data.points[i].meas - uv;
      }
      init = chain.effects[k]->Initial(data, residual);
    }
    constexpr double kInf = std::numeric_limits<double>::infinity();
    std::vector<double> lo(size, -kInf), hi(size, kInf);
    chain.effects[k]->Bounds(data, &lo, &hi);
    for (int j = 0; j < size; ++j) {
      const double v = std::isfinite(init[j]) ? init[j] : 0.0;
      theta[chain.begin[k] + j] = std::clamp(v, lo[j], hi[j]);
    }
  }
  return theta;
}

// theta per z: the inverse rms movement of the modelled points per unit of the parameter at
// the start. The trial step grows until the movement is well above rounding; a parameter that
// moves nothing there (a centre while its effect is zero) keeps its own unit.
std::vector<double> ParameterScale(const FieldData& data, const Chain& chain,
                                   const std::vector<double>& theta) {
  std::vector<double> scale(theta.size(), 1.0);
  std::vector<Vector2d> plus, minus;
  const double count = 2.0 * static_cast<double>(data.points.size());
  for (size_t j = 0; j < theta.size(); ++j) {
    double step = std::max(1e-6 * std::abs(theta[j]), 1e-9);
    for (int attempt = 0; attempt < 5; ++attempt, step *= 1e3) {
      std::vector<double> t = theta;
      t[j] = theta[j] + step;
      Model(data, chain, t, &plus);
      t[j] = theta[j] - step;
      Model(data, chain, t, &minus);
      double sum2 = 0.0, max_abs = 0.0;
      for (size_t i = 0; i < plus.size(); ++i) {
        const Vector2d d = plus[i] - minus[i];
        sum2 += d.squaredNorm();
        max_abs = std::max(max_abs, d.cwiseAbs().maxCoeff());
      }
      if (!std::isfinite(sum2)) break;
      if (max_abs > 1e-9) {
        scale[j] = 2.0 * step / std::sqrt(sum2 / count);
        break;
      }
    }
  }
  return scale;
}

FieldData Subset(const FieldData& data, const std::vector<int>& use) {
  FieldData sub;
  sub.origin = data.origin;
  sub.has_z = data.has_z;
  sub.has_t = data.has_t;
  sub.has_v = data.has_v;
  sub.points.reserve(use.size());
  for (int i : use) sub.points.push_back(data.points[i]);
  return sub;
}

std::string MissingColumn(const Effect& e) {
  if (e.name() == "thermal_drift") return "t_s";
  if (e.name() == "tracking_lag") return "vx_mm_s, vy_mm_s";
  if (e.name() == "focus_scale") return "z_cmd_mm";
  return "a column it needs";
}

}  // namespace

Status FitOptions::Validate() const {
  if (max_iterations < 1) {
    return InvalidArgument("fit options: max_iterations must be >= 1, got " +
                           std::to_string(max_iterations));
  }
  return Status::Ok();
}

Result<FitResult> FitEffects(const FieldData& data, const std::vector<const Effect*>& effects,
                             const std::vector<int>& use, const FitOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  for (const Effect* e : effects) {
    if (e == nullptr) return InvalidArgument("fit: null effect");
    if (!e->Applicable(data)) {
      return InvalidArgument("fit: effect " + e->name() + " does not apply to " + data.origin +
                             ": the data has no " + MissingColumn(*e));
    }
  }
  for (int i : use) {
    if (i < 0 || i >= static_cast<int>(data.points.size())) {
      return InvalidArgument("fit: point index " + std::to_string(i) + " outside " + data.origin +
                             " (" + std::to_string(data.points.size()) + " points)");
    }
  }
  std::vector<int> index = use;
  if (index.empty()) {
    index.resize(data.points.size());
    std::iota(index.begin(), index.end(), 0);
  }
  const FieldData sub = Subset(data, index);
  const Chain chain(effects);
  const int n = static_cast<int>(sub.points.size());
  const int p = chain.parameters();
  if (2 * n < p + 1) {
    return FailedPrecondition("fit: " + std::to_string(n) + " points (" + std::to_string(2 * n) +
                              " residuals) of " + data.origin + " cannot determine " +
                              std::to_string(p) + " parameters (need >= parameters + 1)");
  }

  FitResult result;
  result.points = n;
  result.parameters = p;
  std::vector<double> theta = InitialTheta(sub, chain, options.start);
  std::vector<double> se(p, std::numeric_limits<double>::quiet_NaN());

  if (p == 0) {
    result.summary = "nominal model: no parameters to fit";
  } else {
    const std::vector<double> scale = ParameterScale(sub, chain, theta);
    std::vector<std::vector<double>> z(chain.size());
    std::vector<double*> blocks;
    for (int k = 0; k < chain.size(); ++k) {
      for (int j = chain.begin[k]; j < chain.begin[k + 1]; ++j) z[k].push_back(theta[j] / scale[j]);
      blocks.push_back(z[k].data());
    }
    auto* cost = new FieldCost(sub, chain, scale);
    ceres::Problem problem;
    problem.AddResidualBlock(cost, nullptr, blocks);
    ceres::Solver::Options so;
    so.minimizer_type = ceres::TRUST_REGION;
    so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    so.minimizer_progress_to_stdout = false;
    // Noise-limited fits of a few effects: a relative cost change of 1e-10 leaves the
    // parameters within ~1e-5 of their standard error of the minimum.
    so.function_tolerance = 1e-10;
    so.parameter_tolerance = 1e-10;
    so.gradient_tolerance = 1e-14;
    BoundParameters(sub, chain, scale, &z, &problem);
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    result.summary = summary.BriefReport();
    if (summary.termination_type != ceres::CONVERGENCE) {
      return FailedPrecondition(
          "fit of " + std::to_string(p) + " parameters to " + data.origin + " did not converge: " +
          summary.BriefReport());
    }
    for (int k = 0; k < chain.size(); ++k) {
      for (int j = chain.begin[k]; j < chain.begin[k + 1]; ++j) {
        theta[j] = scale[j] * z[k][j - chain.begin[k]];
      }
    }
    if (options.compute_stderr) {
      Eigen::MatrixXd jac(2 * n, p);
      std::vector<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> jk(
          chain.size());
      std::vector<double*> jptr;
      for (int k = 0; k < chain.size(); ++k) {
        jk[k].resize(2 * n, chain.begin[k + 1] - chain.begin[k]);
        jptr.push_back(jk[k].data());
      }
      std::vector<double> res(2 * n);
      if (cost->Evaluate(blocks.data(), res.data(), jptr.data())) {
        for (int k = 0; k < chain.size(); ++k) jac.middleCols(chain.begin[k], jk[k].cols()) = jk[k];
        double rss = 0.0;
        for (double r : res) rss += r * r;
        const std::vector<double> se_z = StandardErrorsZ(jac, rss / (2.0 * n - p));
        for (int j = 0; j < p; ++j) se[j] = scale[j] * se_z[j];
      }
    }
  }

  std::vector<Vector2d> model;
  Model(sub, chain, theta, &model);
  double rss = 0.0;
  for (int i = 0; i < n; ++i) rss += (sub.points[i].meas - model[i]).squaredNorm();
  result.rss_mm2 = rss;
  result.rms_mm = n > 0 ? std::sqrt(rss / n) : 0.0;

  result.effects.resize(effects.size());
  for (int k = 0; k < chain.size(); ++k) {
    EffectFit& f = result.effects[chain.given[k]];
    f.name = chain.effects[k]->name();
    f.param_names = chain.effects[k]->param_names();
    f.params.assign(theta.begin() + chain.begin[k], theta.begin() + chain.begin[k + 1]);
    f.stderrs.assign(se.begin() + chain.begin[k], se.begin() + chain.begin[k + 1]);
  }
  return result;
}

Eigen::Vector2d Predict(const FieldPoint& point, const std::vector<const Effect*>& effects,
                        const std::vector<EffectFit>& fits) {
  assert(fits.size() == effects.size());
  const Chain chain(effects);
  std::vector<double> theta;
  theta.reserve(chain.parameters());
  for (int g : chain.given) {
    assert(fits[g].params.size() == effects[g]->param_names().size());
    theta.insert(theta.end(), fits[g].params.begin(), fits[g].params.end());
  }
  Vector2d uv = point.cmd;
  chain.ApplyFrom(0, point, theta.data(), &uv);
  return uv;
}

}  // namespace insitu::fit
