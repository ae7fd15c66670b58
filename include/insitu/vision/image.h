// A non-owning view of an image (8-bit, or 16-bit holding 10..16-bit samples), row-major, mono
// unless its format says otherwise (the finders read mono images only and refuse others by
// name: vision/colour.h reduces a colour frame to its laser's channel); an image that owns its
// samples; a camera Frame seen as a view.
// Pixel (u, v): u is the column (0..width-1, left to right), v the row (top to bottom); the
// centre of pixel (u, v) is at image coordinates (u, v), as in OpenCV.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "insitu/core/frame.h"

namespace insitu::vision {

struct ImageView {
  const void* data = nullptr;
  int width = 0;
  int height = 0;
  size_t stride_bytes = 0;  // bytes from one row to the next
  int bit_depth = 8;        // 8 (uint8 samples) or 10..16 (uint16 samples)
  PixelFormat format = PixelFormat::kMono;

  bool is_8bit() const { return bit_depth == 8; }
  int bytes_per_pixel() const { return SamplesPerPixel(format) * (is_8bit() ? 1 : 2); }
  int max_value() const { return (1 << bit_depth) - 1; }
  const uint8_t* row8(int v) const {
    return static_cast<const uint8_t*>(data) + static_cast<size_t>(v) * stride_bytes;
  }
  const uint16_t* row16(int v) const {
    return reinterpret_cast<const uint16_t*>(static_cast<const uint8_t*>(data) +
                                             static_cast<size_t>(v) * stride_bytes);
  }
  // The pixels [x, x + w) x [y, y + h), which the caller keeps inside this view; pixel (u, v)
  // of the crop is pixel (x + u, y + v) here.
  ImageView Crop(int x, int y, int w, int h) const {
    const size_t offset =
        static_cast<size_t>(y) * stride_bytes + static_cast<size_t>(x) * bytes_per_pixel();
    return {static_cast<const uint8_t*>(data) + offset,
            w,
            h,
            stride_bytes,
            bit_depth,
            BayerShifted(format, x, y)};
  }
};

// An image that owns its samples, rows packed.
struct Image {
  int width = 0;
  int height = 0;
  int bit_depth = 8;           // as ImageView's
  std::vector<uint8_t> bytes;  // width * height pixels of SamplesPerPixel(format) samples of 1
                               // (8-bit) or 2 bytes
  PixelFormat format = PixelFormat::kMono;

  ImageView view() const& {
    return {bytes.data(),
            width,
            height,
            static_cast<size_t>(width) * SamplesPerPixel(format) * (bit_depth == 8 ? 1 : 2),
            bit_depth,
            format};
  }
  // A temporary image's view would dangle.
  ImageView view() const&& = delete;
};

// A camera frame's samples as a view; valid while `frame` lives and its bytes do not change.
inline ImageView ViewOf(const Frame& frame) {
  return {frame.bytes.data(),   frame.width,     frame.height,
          frame.stride_bytes(), frame.bit_depth, frame.format};
}
// A temporary frame's view would dangle.
ImageView ViewOf(const Frame&&) = delete;

}  // namespace insitu::vision
