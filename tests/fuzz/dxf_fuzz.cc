// libFuzzer target for the DXF reader: a drawing from the outside must never crash, hang or
// read out of bounds; every error names the file; every drawn point is finite.
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
  if (size > 200000) return 0;  // a flattened drawing of that many bytes says nothing more
  const std::string text(reinterpret_cast<const char*>(data), size);
  // A coarse tolerance: flattening is not what is fuzzed, the parser is.
  auto parsed = insitu::pattern::ParseDxf(text, "fuzz.dxf", 0.05);
  if (!parsed.ok()) {
    Check(parsed.status().message().find("fuzz.dxf") != std::string::npos);
    return 0;
  }
  for (const auto& path : parsed->paths) {
    for (const auto& p : path.points) Check(std::isfinite(p.x()) && std::isfinite(p.y()));
  }
  return 0;
}
