// Height calibration lookup (seed 000 sec. 2.2, eq. 5-6), per image column.
//
// The seed moves the Z stage to known heights, projects lines at known offsets x, and relates
// the stripe's mean pixel offset P = P1(x) + P2 to the height: Z = f(x, P2). insitu keeps the
// same measurements but not only their mean: for every (line offset x_i, stage height z_j)
// it stores the stripe's whole image curve v = c_ij(u) (a degree-5 polynomial in the column),
// so the height of a stripe point at column u follows from the curves of its own line
// (cubic interpolation across the neighbouring offsets x_i) and where its v falls among them
// (cubic interpolation in v). That removes what the mean cannot: the variation along the line (lens distortion,
// the curved light sheet, pose error), which is what makes method 1's error grow toward the
// ends of the line. Pixels in full-sensor coordinates (OpenCV convention); mm in the galvo
// frame (the stage plate at height z is the galvo plane z).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::calib {

// One calibration frame: the line at offset `line_x_mm` on the plate at `stage_z_mm`, and the
// valid stripe centres (u, v) in full-sensor pixels.
struct HeightObservation {
  double line_x_mm = 0.0;
  double stage_z_mm = 0.0;
  std::vector<Eigen::Vector2d> centres;
};

struct StripeCurve {
  double u_min = 0.0, u_max = 0.0;
  std::vector<double> coeffs;  // v = sum c_k t^k, t = (2u - u_min - u_max) / (u_max - u_min)
  double Eval(double u) const;
};

struct HeightLookupSummary {
  bool ok = false;
  std::string message;
  double fit_rms_px = 0.0;   // residual of the curves through their centres (outliers out)
  double fit_max_px = 0.0;
  int outliers = 0;          // centres left out of their curve's fit (far off it)
};

class HeightLookup {
 public:
  HeightLookup() = default;
  // Needs a full grid: every offset at every height (>= 4 of each, for cubic interpolation).
  static HeightLookup Build(const std::vector<HeightObservation>& observations,
                            HeightLookupSummary* summary);

  // Height of a stripe point of the line at `line_x_mm` seen at pixel (u, v); empty outside
  // the calibrated volume (more than half a step beyond the outer offsets or heights, or a
  // column the calibration lines did not reach).
  std::optional<double> Height(double line_x_mm, double u, double v) const;

  bool empty() const { return xs_.empty(); }
  const std::vector<double>& line_x_mm() const { return xs_; }
  const std::vector<double>& stage_z_mm() const { return zs_; }
  const std::vector<StripeCurve>& curves() const { return curves_; }  // x-major
  // From stored parts (calibration file); errors say what is inconsistent.
  static Result<HeightLookup> FromParts(std::vector<double> xs, std::vector<double> zs,
                                        std::vector<StripeCurve> curves);

 private:
  std::vector<double> xs_, zs_;
  std::vector<StripeCurve> curves_;  // curves_[i * zs_.size() + j]
};

}  // namespace insitu::calib
