// "+" crosses of a calibration reticle in an image (seed 001 sec. 3.3 and 4.2): each cross
// centre to a small fraction of a pixel, for the coaxial camera's field calibration.
//
// Seed 001 binarises the image and takes each line's middle between its two edge tangents.
// Here each line of a cross is located by gray-level centroids across it (the profile's
// centre of mass above the local background, in a window held symmetric about the line),
// a straight line is fitted to those centres along each bar, and the cross's centre is where
// the two lines meet: every pixel of a bar votes, so noise averages down over the bar's
// length, and no threshold decides where a line is (the threshold only finds the crosses).
//
// Pixel coordinates as in OpenCV: the centre of pixel (u, v) is at (u, v); u right, v down.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

struct CrossOptions {
  // Crosses brighter than their background (chrome crosses on glass in bright-field light);
  // false for dark lines on a bright field.
  bool bright = true;
  // Widest line (full width of its blurred image, pixels): the background filter is made
  // wider than this, and the centroid window follows from it.
  double max_line_width_px = 8.0;
  // Accepted bar length (tip to tip) of a cross, pixels.
  double min_bar_px = 24.0;
  double max_bar_px = 2000.0;
  // Least line peak over the local background, as a fraction of full scale
  // (ImageView::max_value()), so one setting serves 8- and 12-bit frames.
  double min_contrast_fraction = 0.05;
  // A cross whose blob comes within this many pixels of the image edge is not reported: a
  // bar cut by the edge has lost its end and its centre would rest on fewer samples.
  int border_px = 2;

  // invalid_argument naming the field.
  Status Validate() const;
};

struct Cross {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();  // where the two line centres meet
  // Directions of the two lines, degrees from +u toward +v: the first in (-45, 45], the
  // second near the first + 90.
  double angle_deg = 0.0;
  double angle2_deg = 90.0;
  double bar_px = 0.0;       // mean length of the two bars (extent of the cross's blob)
  double contrast = 0.0;     // median line peak over the local background, gray levels
  double background = 0.0;   // the local background, gray levels
  double residual_px = 0.0;  // rms of the line-centre samples about their two lines
  int samples = 0;           // line-centre samples used, both lines
};

// Every cross found whole in the image, ordered by row then column of its centre. No cross
// is not an error (an empty list). Errors: invalid_argument for options or an empty image.
Result<std::vector<Cross>> FindCrosses(const ImageView& image, const CrossOptions& options = {});

}  // namespace insitu::vision
