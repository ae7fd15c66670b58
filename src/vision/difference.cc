#include "insitu/vision/difference.h"

#include <algorithm>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "insitu/core/robust.h"
#include "vision/image_cv.h"

namespace insitu::vision {
namespace {

cv::Mat MatOf(const ImageView& image) {
  return cv::Mat(image.height, image.width, image.is_8bit() ? CV_8UC1 : CV_16UC1,
                 const_cast<void*>(image.data), image.stride_bytes);
}

}  // namespace

Result<Darkened> FindDarkened(const ImageView& before, const ImageView& after) {
  INSITU_RETURN_IF_ERROR(CheckImageView(before, "darkened: before: "));
  INSITU_RETURN_IF_ERROR(CheckImageView(after, "darkened: after: "));
  if (before.width != after.width || before.height != after.height) {
    return InvalidArgument("darkened: the views differ in size");
  }
  Darkened out;
  try {
    cv::Mat diff;
    cv::subtract(MatOf(before), MatOf(after), diff, cv::noArray(), CV_32F);
    // The level and noise in float, as the difference is.
    std::vector<float> values(diff.begin<float>(), diff.end<float>());
    const float level = static_cast<float>(MedianInPlace(values));
    const double sigma =
        std::max(0.5, kMadToSigma * MedianAbsDeviationFrom(std::move(values), level));
    cv::Mat smooth;
    cv::blur(diff, smooth, cv::Size(3, 3));
    for (int y = 0; y < diff.rows; ++y) {
      for (int x = 0; x < diff.cols; ++x) {
        if (smooth.at<float>(y, x) - level > 5.0 * sigma / 3.0) {
          out.px.emplace_back(x, y);
          out.depth.push_back(diff.at<float>(y, x) - level);
        }
      }
    }
  } catch (const cv::Exception& e) {
    return InvalidArgument(std::string("darkened: ") + e.what());
  }
  return out;
}

}  // namespace insitu::vision
