// libFuzzer target for the HPGL/PLT reader: plotter files from the outside must never crash,
// hang or read out of bounds; every error names the file; every drawn point is finite.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "insitu/pattern/vector.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto parsed = insitu::pattern::ParseHpgl(text, "fuzz.plt");
  if (!parsed.ok()) {
    Check(parsed.status().message().find("fuzz.plt") != std::string::npos);
    return 0;
  }
  for (const auto& path : parsed->paths) {
    for (const auto& p : path.points) Check(std::isfinite(p.x()) && std::isfinite(p.y()));
  }
  return 0;
}
