// A non-owning view of a mono image (8-bit, or 16-bit holding 12-bit samples), row-major.
// Pixel (u, v): u is the column (0..width-1, left to right), v the row (top to bottom); the
// centre of pixel (u, v) is at image coordinates (u, v), as in OpenCV.
#pragma once

#include <cstddef>
#include <cstdint>

namespace insitu::vision {

struct ImageView {
  const void* data = nullptr;
  int width = 0;
  int height = 0;
  size_t stride_bytes = 0;  // bytes from one row to the next
  int bit_depth = 8;        // 8 (uint8 samples) or 10..16 (uint16 samples)

  bool is_8bit() const { return bit_depth == 8; }
  int max_value() const { return (1 << bit_depth) - 1; }
  const uint8_t* row8(int v) const {
    return static_cast<const uint8_t*>(data) + static_cast<size_t>(v) * stride_bytes;
  }
  const uint16_t* row16(int v) const {
    return reinterpret_cast<const uint16_t*>(static_cast<const uint8_t*>(data) +
                                             static_cast<size_t>(v) * stride_bytes);
  }
};

}  // namespace insitu::vision
