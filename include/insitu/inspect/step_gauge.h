// Accuracy of a scan of the seed's step gauge (seed 000 sec. 3.2, Fig. 5): steps side by side
// along x (first height at -x), each running the gauge's full length along y, placed by the
// operator at a nominal centre. Heights are absolute above the stage plate (z = 0 in the galvo
// frame when the stage is at 0).
#pragma once

#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/geometry/cloud.h"

namespace insitu::inspect {

struct StepGaugeSpec {
  std::vector<double> heights_mm{3.0, 5.0, 10.0, 15.0};
  double step_width_mm = 5.0;
  double length_mm = 80.0;
  double center_x_mm = 0.0;
  double center_y_mm = 0.0;
  double base_z_mm = 0.0;
  // Points closer than this to a step's edges are left out of the height statistics
  // (placement tolerance + half the beam).
  double edge_margin_mm = 1.0;
  double bin_mm = 1.0;  // y bins of the error-along-the-line curves

  Status Validate() const;
};

struct StepResult {
  double nominal_mm = 0.0;
  int points = 0;
  double mean_error_mm = 0.0;
  double max_abs_error_mm = 0.0;
  double rms_error_mm = 0.0;
  std::vector<double> bin_y_mm;           // bin centres
  std::vector<double> bin_mean_error_mm;  // NaN where a bin is empty
};

struct StepGaugeResult {
  std::vector<StepResult> steps;
  int points = 0;
  double max_abs_error_mm = 0.0;
  double rms_error_mm = 0.0;
  // Largest |mean error| of any bin_mm slice along y of any step: the curves of seed 000
  // Fig. 5b, where single-point noise (speckle) averages out.
  double max_abs_binned_error_mm = 0.0;
  int length_lines = 0;          // scan lines that crossed a top over its whole length
  // Mean over those lines of the distance between the top's two ends, each where the stripe
  // on the top falls to half its brightness (see inspect/line_ends.h).
  double length_mm = 0.0;
  double length_std_mm = 0.0;
};

// Errors: invalid_argument if no step received any point (wrong placement or empty cloud).
Result<StepGaugeResult> EvaluateStepGauge(const geometry::Cloud& cloud, const StepGaugeSpec& spec);

}  // namespace insitu::inspect
