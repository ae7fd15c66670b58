// libFuzzer target for pattern images: bytes from the outside go through OpenCV's decoders and
// insitu's threshold and dither; nothing may crash, throw or read out of bounds, every error
// names the file, and an accepted mask is as large as it says with something to mark.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "insitu/pattern/raster.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  // The first byte picks the reading (threshold, invert, dither); the rest is the file.
  const int threshold = data[0];
  const bool invert = (data[0] & 1) != 0, dither = (data[0] & 2) != 0;
  const std::string bytes(reinterpret_cast<const char*>(data + 1), size - 1);
  auto mask = insitu::pattern::DecodeRasterMask(bytes, "fuzz.png", threshold, invert, dither);
  if (!mask.ok()) {
    Check(mask.status().message().find("fuzz.png") != std::string::npos);
    return 0;
  }
  Check(mask->width > 0 && mask->height > 0);
  Check(mask->on.size() == static_cast<size_t>(mask->width) * mask->height);
  return 0;
}
