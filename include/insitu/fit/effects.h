// The effect library for the galvo field (CONTRACT.md, "Canonical effects"): each effect is a
// small, named deformation of where the spot lands, with its parameters, physical meaning and
// origin documented in docs/model.md. The nominal model is the simulator's galvo model at its
// as-designed values, where the head's own correction makes the spot land on the command:
// u = x, v = y. A model is the nominal one plus a set of effects, applied in a fixed order of
// stages (additive distortions, then rotation, then perspective) whatever order they are
// listed in.
//
// Forms (mm; x, y, z the command, t the time, vx, vy the beam velocity):
//   offset             dx, dy         u += dx; v += dy
//   scale              sx, sy         u += sx x; v += sy y
//   rotation           theta          (u, v) rotated by theta (rad) about the origin
//   skew               gamma          u += gamma y
//   mirror_separation  kappa, x0, y0  u += kappa (x - x0) (y - y0)^2
//   lens_radial        k, x0, y0      (u, v) += k r^2 (x - x0, y - y0), r^2 = (x-x0)^2 + (y-y0)^2
//   perspective        p, q           w = 1 + p x + q y; u /= w; v /= w
//   thermal_drift      ox, oy, g      u += t (ox + g x); v += t (oy + g y)     (needs t_s)
//   tracking_lag       tau            u -= tau vx; v -= tau vy                  (needs vx, vy)
//   focus_scale        c              u += c z x; v += c z y                    (needs z_cmd_mm)
// Beyond the contract's table:
//   head_distortion    kappa, k, x0, y0   mirror_separation and lens_radial about one centre
//   head_geometry      f_mm .. gy         the exact two-mirror f-theta head (scan_head.h)
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "insitu/fit/field_data.h"

namespace insitu::fit {

class Effect {
 public:
  virtual ~Effect() = default;

  virtual std::string name() const = 0;
  virtual std::vector<std::string> param_names() const = 0;
  // One line: what it is and where it comes from (scan head or measuring set-up).
  virtual std::string meaning() const = 0;
  // Order in a model: 0 additive, 1 rotation, 2 perspective.
  virtual int stage() const = 0;
  // False when the data lacks a column the effect needs (t_s, vx/vy, z_cmd_mm).
  virtual bool Applicable(const FieldData& /*data*/) const { return true; }
  // Starting values for a fit, from the data and the residual of the model so far
  // (residual[i] = meas - model for point i).
  virtual std::vector<double> Initial(const FieldData& data,
                                      const std::vector<Eigen::Vector2d>& residual) const = 0;
  // Where a fit may take the parameters: `lo` and `hi` come in as -inf and +inf, one per
  // parameter; an effect narrows them to what is physical (a centre within the measured
  // field, a focal length that is one).
  virtual void Bounds(const FieldData& /*data*/, std::vector<double>* /*lo*/,
                      std::vector<double>* /*hi*/) const {}
  // Moves the modelled position `uv` of point `p` by the effect with `params`.
  virtual void Apply(const FieldPoint& p, const double* params, Eigen::Vector2d* uv) const = 0;
};

// Every effect of the library, in a fixed order (the canonical ones first).
std::vector<std::unique_ptr<Effect>> EffectLibrary();
// The effect of that name, or nullptr.
std::unique_ptr<Effect> MakeEffect(const std::string& name);

}  // namespace insitu::fit
