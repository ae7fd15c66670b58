#include "insitu/vision/canvas.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "vision/image_cv.h"

namespace insitu::vision {

// A drawing call OpenCV refuses (a bad argument) cannot report through a void method: its
// message is kept, shared with the regions of the canvas, and WritePng returns it.
struct Canvas::Impl {
  cv::Mat bgr;  // CV_8UC3
  std::shared_ptr<std::string> error = std::make_shared<std::string>();

  template <typename Draw>
  void Try(Draw&& draw) {
    try {
      draw();
    } catch (const cv::Exception& e) {
      if (error->empty()) *error = e.what();
    }
  }
};

namespace {

cv::Scalar Bgr(int rgb) { return cv::Scalar(rgb & 0xFF, (rgb >> 8) & 0xFF, (rgb >> 16) & 0xFF); }

// Rounded to the nearest pixel as OpenCV rounds a cv::Point2d.
cv::Point Px(const Eigen::Vector2d& p) { return cv::Point(cv::Point2d(p.x(), p.y())); }

int LineType(const Pen& pen) { return pen.smooth ? cv::LINE_AA : cv::LINE_8; }

int Interpolation(double factor) { return factor < 1.0 ? cv::INTER_AREA : cv::INTER_CUBIC; }

}  // namespace

int RgbOf(double r, double g, double b) {
  return cv::saturate_cast<uchar>(r) << 16 | cv::saturate_cast<uchar>(g) << 8 |
         cv::saturate_cast<uchar>(b);
}

Canvas::Canvas(int width, int height, int rgb) : impl_(std::make_unique<Impl>()) {
  impl_->Try([&] { impl_->bgr = cv::Mat(height, width, CV_8UC3, Bgr(rgb)); });
}

Canvas::Canvas(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Canvas::Canvas(Canvas&&) noexcept = default;
Canvas& Canvas::operator=(Canvas&&) noexcept = default;
Canvas::~Canvas() = default;

Result<Canvas> Canvas::FromGray(const ImageView& image, double zoom) {
  INSITU_RETURN_IF_ERROR(CheckImageView(image, "canvas: "));
  if (!(zoom > 0)) return InvalidArgument("canvas: zoom must be > 0");
  auto impl = std::make_unique<Impl>();
  try {
    const cv::Mat gray(image.height, image.width, image.is_8bit() ? CV_8UC1 : CV_16UC1,
                       const_cast<void*>(image.data), image.stride_bytes);
    cv::Mat g8;
    gray.convertTo(g8, CV_8U, image.is_8bit() ? 1.0 : 255.0 / image.max_value());
    if (zoom != 1.0) cv::resize(g8, g8, cv::Size(), zoom, zoom, Interpolation(zoom));
    cv::cvtColor(g8, impl->bgr, cv::COLOR_GRAY2BGR);
  } catch (const cv::Exception& e) {
    return InvalidArgument(std::string("canvas: ") + e.what());
  }
  return Canvas(std::move(impl));
}

int Canvas::width() const { return impl_->bgr.cols; }
int Canvas::height() const { return impl_->bgr.rows; }

Canvas Canvas::Clone() const {
  auto impl = std::make_unique<Impl>();
  impl->bgr = impl_->bgr.clone();
  *impl->error = *impl_->error;
  return Canvas(std::move(impl));
}

Canvas Canvas::Region(int x, int y, int width, int height) {
  auto impl = std::make_unique<Impl>();
  impl->error = impl_->error;
  impl_->Try([&] { impl->bgr = impl_->bgr(cv::Rect(x, y, width, height)); });
  return Canvas(std::move(impl));
}

void Canvas::Line(const Eigen::Vector2d& from, const Eigen::Vector2d& to, const Pen& pen) {
  impl_->Try(
      [&] { cv::line(impl_->bgr, Px(from), Px(to), Bgr(pen.rgb), pen.thickness, LineType(pen)); });
}

void Canvas::Arrow(const Eigen::Vector2d& from, const Eigen::Vector2d& to, const Pen& pen,
                   double tip_fraction) {
  impl_->Try([&] {
    cv::arrowedLine(impl_->bgr, Px(from), Px(to), Bgr(pen.rgb), pen.thickness, LineType(pen), 0,
                    tip_fraction);
  });
}

void Canvas::Circle(const Eigen::Vector2d& centre, int radius_px, const Pen& pen) {
  impl_->Try([&] {
    cv::circle(impl_->bgr, Px(centre), radius_px, Bgr(pen.rgb), pen.thickness, LineType(pen));
  });
}

void Canvas::Rectangle(int x, int y, int width, int height, const Pen& pen) {
  impl_->Try([&] {
    cv::rectangle(impl_->bgr, cv::Rect(x, y, width, height), Bgr(pen.rgb), pen.thickness,
                  LineType(pen));
  });
}

void Canvas::Cross(const Eigen::Vector2d& centre, int size_px, const Pen& pen) {
  impl_->Try([&] {
    cv::drawMarker(impl_->bgr, Px(centre), Bgr(pen.rgb), cv::MARKER_CROSS, size_px, pen.thickness,
                   LineType(pen));
  });
}

void Canvas::Text(const std::string& text, const Eigen::Vector2d& origin, double scale,
                  const Pen& pen) {
  impl_->Try([&] {
    cv::putText(impl_->bgr, text, Px(origin), cv::FONT_HERSHEY_SIMPLEX, scale, Bgr(pen.rgb),
                pen.thickness, LineType(pen));
  });
}

TextSize Canvas::MeasureText(const std::string& text, double scale, int thickness) {
  int baseline = 0;
  const cv::Size size =
      cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, thickness, &baseline);
  return {size.width, size.height};
}

void Canvas::Resize(double factor) {
  impl_->Try([&] {
    cv::Mat out;
    cv::resize(impl_->bgr, out, cv::Size(), factor, factor, Interpolation(factor));
    impl_->bgr = out;
  });
}

void Canvas::Blend(const Canvas& overlay, double weight) {
  impl_->Try([&] {
    cv::addWeighted(overlay.impl_->bgr, weight, impl_->bgr, 1.0 - weight, 0.0, impl_->bgr);
  });
}

Status Canvas::WritePng(const std::string& path) const {
  if (!impl_->error->empty()) {
    return DeviceError("cannot draw " + path + ": " + *impl_->error);
  }
  return WriteImage(impl_->bgr, path);
}

}  // namespace insitu::vision
