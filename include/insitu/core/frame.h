// One camera frame as the camera backends deliver it: row-major, 8-bit samples or 16-bit
// little-endian samples holding 10..16-bit values; mono, or colour (a Bayer mosaic or three
// samples a pixel) as its pixel format says.
#pragma once

#include <cstdint>
#include <vector>

namespace insitu {

// How a frame's samples carry colour. kMono: one gray sample a pixel. Bayer: one sample a
// pixel behind a colour filter mosaic, named as GenICam's PFNC names it, by the filters of
// the first row's first two pixels and the second row's (kBayerRG: R at (0, 0), G at (1, 0)
// and (0, 1), B at (1, 1)). kRgb, kBgr: three samples a pixel in that order.
enum class PixelFormat : uint8_t { kMono, kBayerRG, kBayerGR, kBayerGB, kBayerBG, kRgb, kBgr };

inline const char* PixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono:
      return "mono";
    case PixelFormat::kBayerRG:
      return "BayerRG";
    case PixelFormat::kBayerGR:
      return "BayerGR";
    case PixelFormat::kBayerGB:
      return "BayerGB";
    case PixelFormat::kBayerBG:
      return "BayerBG";
    case PixelFormat::kRgb:
      return "RGB";
    case PixelFormat::kBgr:
      return "BGR";
  }
  return "unknown";
}
inline int SamplesPerPixel(PixelFormat format) {
  return format == PixelFormat::kRgb || format == PixelFormat::kBgr ? 3 : 1;
}
inline bool IsBayer(PixelFormat format) {
  return format == PixelFormat::kBayerRG || format == PixelFormat::kBayerGR ||
         format == PixelFormat::kBayerGB || format == PixelFormat::kBayerBG;
}
// The mosaic as seen from pixel (x, y) onward: a crop at odd x swaps each row's two filters,
// at odd y the two rows.
inline PixelFormat BayerShifted(PixelFormat format, int x, int y) {
  if (!IsBayer(format)) return format;
  // RG, GR, GB, BG as 0..3: an odd x swaps 0-1 and 2-3, an odd y 0-2 and 1-3.
  static constexpr PixelFormat kByIndex[4] = {PixelFormat::kBayerRG, PixelFormat::kBayerGR,
                                              PixelFormat::kBayerGB, PixelFormat::kBayerBG};
  int k = 0;
  while (kByIndex[k] != format) ++k;
  if (x & 1) k ^= 1;
  if (y & 1) k ^= 2;
  return kByIndex[k];
}

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
  PixelFormat format = PixelFormat::kMono;

  int bytes_per_pixel() const { return SamplesPerPixel(format) * (bit_depth > 8 ? 2 : 1); }
  size_t stride_bytes() const { return static_cast<size_t>(width) * bytes_per_pixel(); }
  int max_value() const { return (1 << bit_depth) - 1; }
  // Sample at (u, v) as an integer gray value (a mono frame's, or the mosaic's).
  int at(int u, int v) const {
    const size_t i = static_cast<size_t>(v) * width + u;
    return bit_depth > 8 ? bytes[2 * i] | (bytes[2 * i + 1] << 8) : bytes[i];
  }
};

}  // namespace insitu
