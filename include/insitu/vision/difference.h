// What darkened between two frames of one view: the side camera before and after marking.
//
// d = before - after per pixel, in gray levels. Most of the view is unchanged, so the median of
// d is its level and sigma = max(0.5, 1.4826 x the median absolute deviation of d) its noise.
// A pixel darkened when the 3 x 3 mean of d (borders reflected) stands above the level by 5
// sigmas of such a mean, 5 sigma / 3.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

struct Darkened {
  std::vector<Eigen::Vector2d> px;  // the darkened pixels, pixel coordinates of the views
  std::vector<double> depth;        // each one's d less the level, gray levels
};

// Errors: invalid_argument for an empty or malformed view, or views of different sizes.
Result<Darkened> FindDarkened(const ImageView& before, const ImageView& after);

}  // namespace insitu::vision
