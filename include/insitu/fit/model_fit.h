// Fitting a set of effects jointly to field data with Ceres (Levenberg-Marquardt, residuals
// meas - model in x and y for every point used), with parameter standard errors from the
// covariance at the solution scaled by the residual variance.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/fit/effects.h"
#include "insitu/fit/field_data.h"

namespace insitu::fit {

struct FitOptions {
  int max_iterations = 200;
  bool compute_stderr = true;
  // Starting values, one entry per effect in the order given (or empty): a non-empty entry
  // (the effect's parameter count) replaces the effect's own Initial(), e.g. the values a
  // model fitted before a new effect joined it. Clamped into the effect's bounds.
  std::vector<std::vector<double>> start;
  Status Validate() const;
};

struct EffectFit {
  std::string name;
  std::vector<std::string> param_names;
  std::vector<double> params;
  std::vector<double> stderrs;  // NaN where the covariance is singular (parameter not defined)
};

struct FitResult {
  std::vector<EffectFit> effects;  // in the order given
  int points = 0;                  // used in the fit
  int parameters = 0;
  double rss_mm2 = 0.0;  // sum of squared residual components (x and y)
  double rms_mm = 0.0;   // sqrt(rss / points): rms of the residual vector length
  std::string summary;   // Ceres's brief report
};

// Fits `effects` (none: the nominal model) to the points of `data` listed in `use` (all when
// empty). Errors: invalid_argument for an effect not applicable to the data or bad options;
// failed_precondition for fewer residuals (2 per point) than parameters + 1, or when the
// solver does not converge (its report in the message): never a silent non-convergence.
Result<FitResult> FitEffects(const FieldData& data, const std::vector<const Effect*>& effects,
                             const std::vector<int>& use = {}, const FitOptions& options = {});

// The modelled measured position of a point for fitted effects (`fits` as FitEffects returned
// them, same order as `effects`).
Eigen::Vector2d Predict(const FieldPoint& point, const std::vector<const Effect*>& effects,
                        const std::vector<EffectFit>& fits);

}  // namespace insitu::fit
