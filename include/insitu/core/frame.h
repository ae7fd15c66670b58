// One camera frame as the camera backends deliver it: mono, row-major, 8-bit samples or
// 16-bit little-endian samples holding 10..16-bit values.
#pragma once

#include <cstdint>
#include <vector>

namespace insitu {

struct Frame {
  int width = 0;
  int height = 0;
  int bit_depth = 8;
  std::vector<uint8_t> bytes;  // width * height * bytes_per_pixel()
  uint64_t sequence = 0;       // frame counter of the camera
  double timestamp_s = 0.0;    // start of exposure, camera clock
  double exposure_us = 0.0;
  double gain_db = 0.0;
  int binning = 1;             // pixels of the full sensor per pixel of this frame, per axis
  // Where the frame's first pixel lies on the sensor, in the frame's (binned) pixels: a region
  // of interest's corner. A pixel (u, v) of the frame is (u + offset_x, v + offset_y) of the
  // whole (binned) sensor.
  int offset_x = 0;
  int offset_y = 0;

  int bytes_per_pixel() const { return bit_depth > 8 ? 2 : 1; }
  size_t stride_bytes() const { return static_cast<size_t>(width) * bytes_per_pixel(); }
  int max_value() const { return (1 << bit_depth) - 1; }
  // Sample at (u, v) as an integer gray value.
  int at(int u, int v) const {
    const size_t i = static_cast<size_t>(v) * width + u;
    return bit_depth > 8 ? bytes[2 * i] | (bytes[2 * i + 1] << 8) : bytes[i];
  }
};

}  // namespace insitu
