// Diagnosis of galvo field data: what the nominal model (the spot lands on the command) gets
// wrong, which effects of the library explain it, how much better the extended model predicts
// points it was not fitted to, and whether structure remains that no effect accounts for.
//
// 1. Noise: from replicates (pooled scatter of repeated commands) when there are any.
// 2. Forward selection: from the nominal model, each applicable effect not yet in the model is
//    fitted jointly with those in it (fit::FitEffects); the one lowering the Bayesian
//    information criterion most, BIC = m ln(RSS / m) + p ln(m) over the m = 2n residual
//    components, enters if it lowers BIC by more than `min_delta_bic` AND lowers the held-out
//    error (k-fold cross-validation; leave-one-out for small sets) by `min_cv_improvement` at
//    least; else the next best candidate is tried. Repeat until nothing enters.
// 3. Unexplained structure in the final residual: with replicates, a lack-of-fit F test (the
//    residual against the replicate scatter); without, the spatial correlation of residual
//    vectors between nearest neighbours against random permutations of them. Either, below
//    `alpha`, sets `unexplained` and the report says where the largest residuals are.
// 4. The cause: the selected effects, strongest first; empty when the nominal model is
//    already within noise.
//
// rms values are of the residual vector length (mm): sqrt(mean |meas - model|^2); noise_mm is
// on the same footing (sqrt(2) times the per-axis standard deviation).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/fit/field_data.h"

namespace insitu::fit {

struct DiagnoseOptions {
  int folds = 5;  // k-fold CV; leave-one-out when points <= loo_max_points
  int loo_max_points = 40;
  double min_delta_bic = 10.0;  // "very strong" evidence (Kass and Raftery)
  // An effect is a cause only if it lowers the held-out rms by this fraction at least: a
  // library effect fitted to part of a foreign pattern helps a little, a real one a lot
  // (an effect at 5x the noise takes the held-out rms down by ~80 %).
  double min_cv_improvement = 0.25;
  int max_effects = 5;
  double alpha = 0.01;     // false-alarm rate of the unexplained-structure tests
  int permutations = 199;  // for the spatial-correlation test
  int neighbours = 4;      // for the spatial-correlation test
  uint64_t seed = 1;       // fold assignment and permutations

  Status Validate() const;
};

struct EffectReport {
  std::string name;
  std::string meaning;
  std::vector<std::string> param_names;
  std::vector<double> params, stderrs;
  double delta_bic = 0.0;  // when it entered (negative: better)
  double cv_rms_mm = 0.0;  // held-out rms of the model once it entered
};

struct Diagnosis {
  std::string origin;
  int n_points = 0;
  double nominal_rms_mm = 0.0, nominal_cv_rms_mm = 0.0;
  std::vector<EffectReport> effects;  // the extended model, in order of entry
  std::vector<std::string> cause;     // names, strongest first
  double extended_rms_mm = 0.0, extended_cv_rms_mm = 0.0;
  double gain = 1.0;         // nominal cv rms / extended cv rms
  double noise_mm = 0.0;     // NaN without replicates
  std::string noise_source;  // "replicates" or "none"
  bool unexplained = false;
  std::string unexplained_test;   // "lack_of_fit", "spatial_correlation"
  double unexplained_p = 1.0;     // p-value of that test
  std::string unexplained_where;  // where the largest residuals are, when unexplained
  // Per row of the data given, a table's reference row too (for plots): meas - nominal model
  // (the command; for a table of moves, plus the offset the moves share), meas - extended model.
  std::vector<Eigen::Vector2d> residual_nominal;
  std::vector<Eigen::Vector2d> residual_extended;
  std::vector<std::string> notes;                  // candidates that failed to fit, and why

  // "the model misses 0.25 mm RMS; cause: two-mirror pincushion (mirror_separation, kappa =
  // ...); extended model 4.1 um held-out; gain 61x".
  std::string Summary() const;
  // report.json as CONTRACT.md specifies (plus a few extra keys).
  std::string ToJson() const;
};

// Errors: invalid_argument for bad options; failed_precondition for fewer than 3 distinct
// commanded positions.
Result<Diagnosis> Diagnose(const FieldData& data, const DiagnoseOptions& options = {});

}  // namespace insitu::fit
