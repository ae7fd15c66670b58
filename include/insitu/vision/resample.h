// Resampling an image through a pixel map: a camera's view of a plane rectified onto the plane
// (the side camera's oblique view of a target, seen square again).
#pragma once

#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

// Where each output pixel comes from: output pixel (c, r) takes the input at pixel position
// (u[r * width + c], v[r * width + c]), input pixel coordinates (see image.h).
struct PixelMap {
  int width = 0;
  int height = 0;
  std::vector<float> u, v;  // width * height each, row-major
};

// Bilinear samples of `image` at the map's positions; positions outside the image read 0.
// The result has the input's bit depth. Errors: invalid_argument for an empty or malformed
// view, or a map whose arrays are not width * height long.
Result<Image> Remap(const ImageView& image, const PixelMap& map);

}  // namespace insitu::vision
