#include "insitu/vision/colour.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <string>

namespace insitu::vision {
namespace {

// The filter colour of mosaic pixel (u, v): 0 red, 1 green, 2 blue.
int FilterAt(PixelFormat format, int u, int v) {
  // The first row's two filters and the second row's, as PixelFormat names them.
  static constexpr std::array<std::array<int, 4>, 4> kMosaic = {{
      {0, 1, 1, 2},  // RG / GB
      {1, 0, 2, 1},  // GR / BG
      {1, 2, 0, 1},  // GB / RG
      {2, 1, 1, 0},  // BG / GR
  }};
  const int k = format == PixelFormat::kBayerRG   ? 0
                : format == PixelFormat::kBayerGR ? 1
                : format == PixelFormat::kBayerGB ? 2
                                                  : 3;
  return kMosaic[k][(v & 1) * 2 + (u & 1)];
}

template <typename T>
void Reduce(const ImageView& in, int colour, Image* out) {
  const int w = in.width, h = in.height;
  T* dst = reinterpret_cast<T*>(out->bytes.data());
  const auto row = [&](int v) {
    return reinterpret_cast<const T*>(static_cast<const uint8_t*>(in.data) +
                                      static_cast<size_t>(v) * in.stride_bytes);
  };
  const auto sample = [&](int u, int v) { return row(v)[u]; };
  if (in.format == PixelFormat::kMono) {
    for (int v = 0; v < h; ++v)
      std::memcpy(dst + static_cast<size_t>(v) * w, row(v), sizeof(T) * w);
    return;
  }
  if (in.format == PixelFormat::kRgb || in.format == PixelFormat::kBgr) {
    const int k = in.format == PixelFormat::kRgb ? colour : 2 - colour;
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) dst[static_cast<size_t>(v) * w + u] = sample(3 * u + k, v);
    }
    return;
  }
  // Bayer: the mean of the samples of that colour among the pixel and its eight neighbours
  // (inside the frame): the pixel's own where it has the colour, else its two or four nearest
  // of it (a green site's two reds lie beside it in a row or a column, a blue site's four on
  // its diagonals, a red or blue site's four greens beside it).
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (FilterAt(in.format, u, v) == colour) {
        dst[static_cast<size_t>(v) * w + u] = sample(u, v);
        continue;
      }
      // Nearest first: the four beside the pixel, then the four on its diagonals.
      double sum = 0.0;
      int n = 0;
      for (int ring = 0; ring < 2 && n == 0; ++ring) {
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            if ((du == 0 && dv == 0) || (ring == 0) != (du == 0 || dv == 0)) continue;
            const int x = u + du, y = v + dv;
            if (x < 0 || y < 0 || x >= w || y >= h || FilterAt(in.format, x, y) != colour) continue;
            sum += sample(x, y);
            ++n;
          }
        }
      }
      dst[static_cast<size_t>(v) * w + u] = n > 0 ? static_cast<T>(sum / n + 0.5) : T{0};
    }
  }
}

}  // namespace

Result<ColourChannel> ChannelOfWavelength(double nm) {
  if (!(nm >= 350.0 && nm <= 1100.0)) {
    return InvalidArgument("laser wavelength " + std::to_string(nm) +
                           " nm: a colour camera's filters separate 350..1100 nm");
  }
  if (nm >= 590.0) return ColourChannel::kRed;
  if (nm >= 490.0) return ColourChannel::kGreen;
  return ColourChannel::kBlue;
}

Status ReduceToChannel(const ImageView& image, ColourChannel channel, Image* out) {
  if (out == nullptr) return InvalidArgument("ReduceToChannel: out is null");
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    return InvalidArgument("colour: empty image");
  }
  if (image.bit_depth != 8 && (image.bit_depth < 10 || image.bit_depth > 16)) {
    return InvalidArgument("colour: bit depth " + std::to_string(image.bit_depth) +
                           " not supported (8, or 10..16 in 16-bit samples)");
  }
  const size_t row = static_cast<size_t>(image.width) * image.bytes_per_pixel();
  if (image.stride_bytes < row) {
    return InvalidArgument(std::string("colour: a ") + PixelFormatName(image.format) + " row of " +
                           std::to_string(image.width) + " pixels needs " + std::to_string(row) +
                           " bytes, the stride is " + std::to_string(image.stride_bytes));
  }
  if (!image.is_8bit() && (image.stride_bytes % 2 != 0 ||
                           reinterpret_cast<uintptr_t>(image.data) % alignof(uint16_t) != 0)) {
    return InvalidArgument("colour: 16-bit samples need 2-byte aligned data and stride");
  }
  out->width = image.width;
  out->height = image.height;
  out->bit_depth = image.bit_depth;
  out->bytes.assign(static_cast<size_t>(image.width) * image.height * (image.is_8bit() ? 1 : 2), 0);
  const int colour = static_cast<int>(channel);
  if (image.is_8bit()) {
    Reduce<uint8_t>(image, colour, out);
  } else {
    Reduce<uint16_t>(image, colour, out);
  }
  return Status::Ok();
}

}  // namespace insitu::vision
