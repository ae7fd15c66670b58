// What the OpenCV-based finders in vision/ share (private to the module): the check of an
// ImageView before it is touched, its samples as a float matrix, and its robust level.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "insitu/core/robust.h"
#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

// invalid_argument, prefixed with `what`, for an empty image, a bit depth other than 8 or
// 10..16 (in 16-bit samples), a colour format, or a stride shorter than a row.
inline Status CheckImageView(const ImageView& image, const std::string& what) {
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    return InvalidArgument(what + "empty image");
  }
  if (image.bit_depth != 8 && (image.bit_depth < 10 || image.bit_depth > 16)) {
    return InvalidArgument(what + "bit depth " + std::to_string(image.bit_depth) +
                           " not supported (8, or 10..16 in 16-bit samples)");
  }
  if (image.format != PixelFormat::kMono) {
    return InvalidArgument(what + "a " + PixelFormatName(image.format) +
                           " frame: this reads one gray plane; reduce the frame to a colour "
                           "channel first (vision::ReduceToChannel)");
  }
  const size_t row = static_cast<size_t>(image.width) * (image.is_8bit() ? 1 : 2);
  if (image.stride_bytes < row) {
    return InvalidArgument(what + "stride " + std::to_string(image.stride_bytes) +
                           " bytes is shorter than a row of " + std::to_string(row) + " bytes");
  }
  return Status::Ok();
}

// A colour view's samples as a gray view (each row's samples side by side), for what acts on
// each sample alone (the room's light averaged and subtracted; a colour frame's checks).
inline ImageView SamplesOf(const ImageView& image) {
  ImageView s = image;
  s.width = image.width * SamplesPerPixel(image.format);
  s.format = PixelFormat::kMono;
  return s;
}

// Writes `image` to `path`, the format from the extension (image_io.cc). Errors: device_error
// naming the file; OpenCV's exceptions end here.
Status WriteImage(const cv::Mat& image, const std::string& path);

// The image's gray levels as CV_32F (a copy).
inline cv::Mat ToFloatMat(const ImageView& image) {
  const cv::Mat src(image.height, image.width, image.is_8bit() ? CV_8UC1 : CV_16UC1,
                    const_cast<void*>(image.data), image.stride_bytes);
  cv::Mat out;
  src.convertTo(out, CV_32F);
  return out;
}

// The level and noise of a background-subtracted CV_32F image, robustly: median and
// 1.4826 x median absolute deviation of the samples every `step` pixels in both directions
// (the targets on it are few and sparse, so they move neither).
inline void RobustLevel(const cv::Mat& image, int step, double* median, double* sigma) {
  std::vector<float> sample;
  for (int v = 0; v < image.rows; v += step) {
    const float* row = image.ptr<float>(v);
    for (int u = 0; u < image.cols; u += step) sample.push_back(row[u]);
  }
  *median = MedianInPlace(sample);
  *sigma = kMadToSigma * MedianAbsDeviationFrom(std::move(sample), static_cast<float>(*median));
}

}  // namespace insitu::vision
