#include "insitu/vision/image_io.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "vision/image_cv.h"

namespace insitu::vision {

// imwrite reports a failed file by returning false and a bad argument or codec by throwing:
// both become the file's device_error here, the one place vision/ writes images.
Status WriteImage(const cv::Mat& image, const std::string& path) {
  try {
    if (!cv::imwrite(path, image)) return DeviceError("cannot write " + path);
  } catch (const cv::Exception& e) {
    return DeviceError("cannot write " + path + ": " + e.what());
  }
  return Status::Ok();
}

Status WritePng(const std::string& path, const ImageView& image) {
  INSITU_RETURN_IF_ERROR(CheckImageView(image, "cannot write " + path + ": "));
  const cv::Mat mat(image.height, image.width, image.is_8bit() ? CV_8UC1 : CV_16UC1,
                    const_cast<void*>(image.data), image.stride_bytes);
  return WriteImage(mat, path);
}

}  // namespace insitu::vision
