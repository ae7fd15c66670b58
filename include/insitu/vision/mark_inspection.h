// Measuring marked lines in a coaxial-camera image (seen from above through the
// scan head).
//
// Frames: the image's pixel (u, v) lies at galvo offset R(rotation) * (u - cx,
// -(v - cy)) * pixel_um from the point the head aims at (cx, cy: the image
// centre), i.e. sensor x along galvo x turned by the camera's mounting
// rotation, rows running down galvo y.
//
// MeasureHatch: in a rectangle around a point, the image is averaged along the
// hatch lines into a profile across them (sampled every quarter pixel); each
// dark line's centre is the vertex of a least-squares parabola through the
// profile's minimum, the spacing is the mean and standard deviation of the
// distances between neighbouring centres, and where the lines are separated
// (the profile between two lines comes back to within 30 % of the unmarked
// level) the width is the full width at half depth below that level.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

struct HatchMeasureOptions {
  double pixel_um = 5.0;                // on the part
  double camera_rotation_deg = 0.0;     // sensor x against galvo x
  double hatch_angle_deg = 0.0;         // direction of the lines in galvo xy
  double spacing_um = 40.0;             // nominal: how far apart lines are looked for
  Eigen::Vector2d centre_px{0.0, 0.0};  // centre of the measured rectangle, image pixels
  double half_length_um = 300.0;        // along the lines (averaged)
  double half_width_um = 300.0;         // across the lines (where centres are sought)
  double unmarked_level = NAN;          // grey level of the bare surface; NaN: from the image

  Status Validate() const;
};

struct HatchMeasurement {
  int lines = 0;
  double spacing_um = 0.0, spacing_std_um = 0.0;
  bool separated = false;  // lines do not overlap: width measurable
  double width_um = NAN, width_std_um = NAN;
  double contrast = 0.0;           // mean line depth over the unmarked level
  std::vector<double> centres_um;  // across the lines, from the rectangle's centre
};

// Errors: invalid_argument for bad options or a rectangle outside the image;
// failed_precondition when fewer than 3 lines are found (nothing marked there,
// or blurred beyond recognition).
Result<HatchMeasurement> MeasureHatch(const ImageView& image, const HatchMeasureOptions& options);

// Focus measure of a square of half-size `half_px` around `centre_px`: the mean
// squared central-difference gradient (Tenengrad), larger when sharper. 8-bit
// images only.
double Sharpness(const ImageView& image, const Eigen::Vector2d& centre_px, int half_px);

// The z of best focus from a sweep: a parabola through log(sharpness) at the
// best sample and its neighbours (a Gaussian focus curve). Errors:
// failed_precondition when the best sample is at either end of the sweep (the
// focus lies outside it) or the curve is flat.
Result<double> BestFocus(const std::vector<double>& z_mm, const std::vector<double>& sharpness);

}  // namespace insitu::vision
