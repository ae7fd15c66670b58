#include "insitu/vision/resample.h"

#include <algorithm>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "vision/image_cv.h"

namespace insitu::vision {

Result<Image> Remap(const ImageView& image, const PixelMap& map) {
  INSITU_RETURN_IF_ERROR(CheckImageView(image, "remap: "));
  const size_t n = static_cast<size_t>(std::max(map.width, 0)) * std::max(map.height, 0);
  if (map.width <= 0 || map.height <= 0 || map.u.size() != n || map.v.size() != n) {
    return InvalidArgument("remap: the map must hold width * height > 0 positions in u and v");
  }
  const int type = image.is_8bit() ? CV_8UC1 : CV_16UC1;
  const cv::Mat src(image.height, image.width, type, const_cast<void*>(image.data),
                    image.stride_bytes);
  const cv::Mat map_u(map.height, map.width, CV_32FC1, const_cast<float*>(map.u.data()));
  const cv::Mat map_v(map.height, map.width, CV_32FC1, const_cast<float*>(map.v.data()));
  Image out;
  out.width = map.width;
  out.height = map.height;
  out.bit_depth = image.bit_depth;
  out.bytes.resize(n * (image.is_8bit() ? 1 : 2));
  // dst wraps out.bytes: remap keeps a buffer of the right size and type.
  cv::Mat dst(map.height, map.width, type, out.bytes.data());
  try {
    cv::remap(src, dst, map_u, map_v, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  } catch (const cv::Exception& e) {
    return InvalidArgument(std::string("remap: ") + e.what());
  }
  return out;
}

}  // namespace insitu::vision
