// What every vector drawing reader's fuzz target checks: arbitrary text must never crash,
// hang or read out of bounds; every error names the file; every drawn point is finite.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "insitu/pattern/vector.h"

namespace insitu::fuzz {

template <typename Parse>
int FuzzVectorReader(const uint8_t* data, size_t size, const std::string& origin, Parse parse) {
  const auto check = [](bool condition) {
    if (!condition) std::abort();
  };
  if (size > 200000) return 0;  // a flattened drawing of that many bytes says nothing more
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto parsed = parse(text, origin);
  if (!parsed.ok()) {
    check(parsed.status().message().find(origin) != std::string::npos);
    return 0;
  }
  for (const auto& path : parsed->paths) {
    for (const auto& p : path.points) check(std::isfinite(p.x()) && std::isfinite(p.y()));
  }
  return 0;
}

}  // namespace insitu::fuzz
