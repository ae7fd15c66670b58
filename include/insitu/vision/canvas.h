// A colour picture to draw a figure on (plots, maps, a camera frame with marks over it) and
// write as PNG: the figures jobs leave next to their reports. OpenCV draws and writes them
// here, so no OpenCV type or exception leaves vision/.
//
// Pixels: x right, y down, (0, 0) the top-left pixel's centre. Points are rounded to the
// nearest pixel. Colours are 0xRRGGBB. Text is OpenCV's Hershey simplex font; `scale` 1.0 is
// about 22 px from the baseline to the top of a capital.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

// A thickness that fills a closed shape (circle, rectangle).
inline constexpr int kFill = -1;

struct Pen {
  int rgb = 0x000000;
  int thickness = 1;    // px, or kFill
  bool smooth = false;  // anti-aliased; else 8-connected, hard-edged
};

// 0xRRGGBB from levels in 0..255, each rounded to the nearest integer and clamped.
int RgbOf(double r, double g, double b);

struct TextSize {
  int width = 0;
  int height = 0;  // baseline to the top of the tallest glyph
};

class Canvas {
 public:
  // `width` x `height` filled with `rgb`.
  Canvas(int width, int height, int rgb = 0xFFFFFF);
  // A camera image as a gray picture (16-bit samples scaled by 255 / max_value), resized by
  // `zoom` first (see Resize). Errors: invalid_argument for an empty or malformed view.
  static Result<Canvas> FromGray(const ImageView& image, double zoom = 1.0);

  Canvas(Canvas&&) noexcept;
  Canvas& operator=(Canvas&&) noexcept;
  ~Canvas();
  // Move-only, so that sharing pixels is said: Region shares them, Clone copies them.
  Canvas(const Canvas&) = delete;
  Canvas& operator=(const Canvas&) = delete;

  int width() const;
  int height() const;

  // A second picture with the same pixels.
  Canvas Clone() const;
  // The rectangle [x, x + width) x [y, y + height) of this canvas (kept inside it) as a canvas
  // of its own that draws onto this one: coordinates from the rectangle's corner, drawing
  // clipped to it.
  Canvas Region(int x, int y, int width, int height);

  void Line(const Eigen::Vector2d& from, const Eigen::Vector2d& to, const Pen& pen);
  // A line with an arrow head at `to`, the head's sides `tip_fraction` of the line's length.
  void Arrow(const Eigen::Vector2d& from, const Eigen::Vector2d& to, const Pen& pen,
             double tip_fraction = 0.1);
  void Circle(const Eigen::Vector2d& centre, int radius_px, const Pen& pen);
  // The outline of (or, with kFill, the whole) rectangle of pixels [x, x + width) x
  // [y, y + height).
  void Rectangle(int x, int y, int width, int height, const Pen& pen);
  // A "+" of `size_px` overall.
  void Cross(const Eigen::Vector2d& centre, int size_px, const Pen& pen);
  // `text` with its baseline's left end at `origin`.
  void Text(const std::string& text, const Eigen::Vector2d& origin, double scale, const Pen& pen);
  static TextSize MeasureText(const std::string& text, double scale, int thickness = 1);

  // Scales the picture by `factor` (> 0): areas averaged when shrinking, bicubic when
  // enlarging.
  void Resize(double factor);
  // this = weight * overlay + (1 - weight) * this, pixel by pixel; the same size.
  void Blend(const Canvas& overlay, double weight);

  // Errors: device_error naming the file: it cannot be encoded or written, or an earlier
  // drawing call on this canvas or a region of it was refused (its message).
  Status WritePng(const std::string& path) const;

 private:
  struct Impl;
  explicit Canvas(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::vision
