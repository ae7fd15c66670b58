// A model extension: library effects with fitted parameters, saved from a diagnosis, applied
// where the galvo model is used. Forward() is where a command lands under the extended model
// (what the simulator uses to carry measured reality); Inverse() is the command that lands on a
// target (what the galvo list emission uses to correct every point). Galvo frame, mm.
//
// File (YAML), written by `insitu diagnose` as extension.yaml:
//   version: 1
//   produced_by: insitu diagnose
//   data: <the data set it was fitted to>
//   effects:
//     - name: mirror_separation
//       params: [1.5e-06, 6.0, -3.0]   # kappa, x0, y0 (the effect's parameter order)
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/fit/diagnose.h"
#include "insitu/fit/effects.h"

namespace insitu::fit {

struct EffectParams {
  std::string name;
  std::vector<double> params;  // in the effect's param_names() order
};

class ModelExtension {
 public:
  ModelExtension() = default;
  // Errors: invalid_argument naming an unknown effect, a wrong parameter count or a
  // non-finite parameter.
  static Result<ModelExtension> Make(const std::vector<EffectParams>& effects);
  // The diagnosis's extended model (empty when it named no cause).
  static Result<ModelExtension> FromDiagnosis(const Diagnosis& diagnosis);

  // Where `point` (its command, focus z, time, velocity) lands under the extended model.
  Eigen::Vector2d Forward(const FieldPoint& point) const;
  Eigen::Vector2d Forward(const Eigen::Vector2d& cmd_mm, double z_mm = 0.0) const;
  // The command that lands on `target_mm`: fixed-point iteration cmd += target - Forward(cmd),
  // converging while the effects' gradients are small against 1 (distortions of a field).
  Eigen::Vector2d Inverse(const Eigen::Vector2d& target_mm, double z_mm = 0.0) const;

  const std::vector<EffectParams>& effects() const { return effects_; }
  bool empty() const { return effects_.empty(); }

 private:
  std::vector<EffectParams> effects_;
  std::vector<std::shared_ptr<const Effect>> impl_;  // same order; applied by stage
};

// Errors: device_error naming the file (written atomically: temporary file, then rename).
Status SaveExtension(const ModelExtension& extension, const std::string& data_origin,
                     const std::string& path);
// Errors: not_found, parse_error, invalid_argument naming the file, line and key.
Result<ModelExtension> LoadExtension(const std::string& path);

}  // namespace insitu::fit
