#include "insitu/vision/background.h"

#include <algorithm>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "vision/image_cv.h"

namespace insitu::vision {
namespace {

// Averaging and subtracting act on each sample alone, so a colour frame keeps its format.
cv::Mat MatOf(const ImageView& image) {
  const ImageView s = SamplesOf(image);
  return cv::Mat(s.height, s.width, s.is_8bit() ? CV_8UC1 : CV_16UC1, const_cast<void*>(s.data),
                 s.stride_bytes);
}

Status CheckSame(const ImageView& a, const ImageView& b, const std::string& what) {
  if (a.width != b.width || a.height != b.height || a.bit_depth != b.bit_depth ||
      a.format != b.format) {
    return InvalidArgument(what + std::to_string(b.width) + " x " + std::to_string(b.height) + " " +
                           PixelFormatName(b.format) + " at " + std::to_string(b.bit_depth) +
                           " bits differs from " + std::to_string(a.width) + " x " +
                           std::to_string(a.height) + " " + PixelFormatName(a.format) + " at " +
                           std::to_string(a.bit_depth) + " bits");
  }
  return Status::Ok();
}

void Resize(const ImageView& like, Image* out) {
  out->width = like.width;
  out->height = like.height;
  out->bit_depth = like.bit_depth;
  out->format = like.format;
  out->bytes.resize(static_cast<size_t>(like.width) * like.height * like.bytes_per_pixel());
}

}  // namespace

Result<Image> AverageFrames(const std::vector<ImageView>& frames) {
  if (frames.empty()) return InvalidArgument("background: no frame to average");
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string what = "background: frame " + std::to_string(i) + ": ";
    INSITU_RETURN_IF_ERROR(CheckImageView(SamplesOf(frames[i]), what));
    INSITU_RETURN_IF_ERROR(CheckSame(frames[0], frames[i], what));
  }
  cv::Mat sum = cv::Mat::zeros(frames[0].height, SamplesOf(frames[0]).width, CV_32F);
  for (const ImageView& f : frames) cv::accumulate(MatOf(f), sum);
  Image out;
  Resize(frames[0], &out);
  const ImageView v = out.view();
  cv::Mat dst = MatOf(v);
  sum.convertTo(dst, dst.type(), 1.0 / static_cast<double>(frames.size()));  // rounds
  return out;
}

Status SubtractBackground(const ImageView& frame, const ImageView& background, Image* out,
                          int saturation_level) {
  INSITU_RETURN_IF_ERROR(CheckImageView(SamplesOf(frame), "background: frame: "));
  INSITU_RETURN_IF_ERROR(CheckImageView(SamplesOf(background), "background: "));
  INSITU_RETURN_IF_ERROR(CheckSame(frame, background, "background: "));
  Resize(frame, out);
  const ImageView v = out->view();
  cv::Mat dst = MatOf(v);
  const cv::Mat raw = MatOf(frame);
  cv::subtract(raw, MatOf(background), dst);  // saturates at 0
  const int clipped = saturation_level > 0 ? std::min(saturation_level, frame.max_value())
                                           : frame.max_value();
  dst.setTo(frame.max_value(), raw >= clipped);
  return Status::Ok();
}

}  // namespace insitu::vision
