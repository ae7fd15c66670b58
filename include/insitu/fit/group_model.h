// Diagnosis of a model whose candidate causes are groups of parameters: the whole cell's
// (job/machine_diagnosis.h), where an effect is a change of the calibration (the camera's pose,
// the head's scale, ...) and the data are residuals of a scan of a known artifact.
//
// The model gives, for parameter values theta (every group's, concatenated; all zero = the
// machine as calibrated), one residual per observation unit. Nuisance groups (where the
// artifact lies) are always fitted. Forward selection as fit::Diagnose does it (fit/diagnose.h):
// each candidate group is fitted jointly with those already in; the one lowering BIC most
// enters if it lowers BIC by more than `min_delta_bic` and the held-out rms (folds of whole
// fold keys: a scan line's residuals are not independent) by `min_cv_improvement`: the pool's,
// or one channel's (GroupModel::channels) without raising the pool's. An entered group is an
// extension of the calibration; its gain is measured on the held-out units.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::fit {

struct ParameterGroup {
  std::string name;                 // a machine-domain effect (CONTRACT.md) or a nuisance
  std::string meaning;              // one line
  std::vector<std::string> params;  // names, with units
  // A typical size of each parameter (its unit of movement): the fit works in theta / scale,
  // and the central-difference step is a small fraction of it.
  std::vector<double> scale;
};

class GroupModel {
 public:
  virtual ~GroupModel() = default;
  virtual int units() const = 0;
  // Units sharing a key are held out together.
  virtual int fold_key(int unit) const = 0;
  // One residual per unit of `use`, in that order, for parameters `theta` (every group's, in
  // the order of the groups given to DiagnoseGroups: nuisance first, then candidates). False
  // when the model cannot be evaluated there (a ray missing its plane).
  virtual bool Residuals(const std::vector<double>& theta, const std::vector<int>& use,
                         std::vector<double>* residuals) const = 0;
  // Observations of different kinds (a scan's heights, pointer spots on the plate) are
  // channels 0 .. channels() - 1: a change only one kind shows must lower that kind's held-out
  // error, not the pool's, where a few spots count for little beside a thousand heights.
  virtual int channels() const { return 1; }
  virtual int channel(int unit) const {
    (void)unit;
    return 0;
  }
};

struct GroupSelectionOptions {
  int folds = 5;
  double min_delta_bic = 10.0;
  double min_cv_improvement = 0.25;
  int max_groups = 4;
  int max_iterations = 100;
  uint64_t seed = 1;  // fold assignment

  Status Validate() const;
};

struct GroupReport {
  std::string name, meaning;
  std::vector<std::string> params;
  std::vector<double> values, stderrs;  // stderr NaN where the data do not determine it
  double delta_bic = 0.0;
  double cv_rms = 0.0;  // held-out rms once it entered
};

struct GroupDiagnosis {
  int units = 0;
  double nominal_rms = 0.0, nominal_cv_rms = 0.0;  // nuisance only
  std::vector<GroupReport> groups;                 // entered, strongest first
  std::vector<GroupReport> nuisance;               // in the final model
  std::vector<std::string> cause;                  // names, strongest first
  double extended_rms = 0.0, extended_cv_rms = 0.0;
  double gain = 1.0;  // nominal cv rms / extended cv rms
  std::vector<double> residual_nominal, residual_extended;  // per unit
  std::vector<std::string> notes;
};

// Errors: invalid_argument (options, a group without parameters or with a scale that is not
// positive), failed_precondition (the nominal model cannot be fitted: too few units).
Result<GroupDiagnosis> DiagnoseGroups(const GroupModel& model,
                                      const std::vector<ParameterGroup>& nuisance,
                                      const std::vector<ParameterGroup>& candidates,
                                      const GroupSelectionOptions& options = {});

}  // namespace insitu::fit
