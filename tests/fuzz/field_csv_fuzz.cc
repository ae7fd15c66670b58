// libFuzzer target for the galvo field CSV reader: arbitrary text must never crash, hang or
// throw; every error names the origin; every accepted data set holds only finite numbers in
// the columns the fits use, and its replicate groups index real points.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "insitu/fit/field_data.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto parsed = insitu::fit::ParseFieldCsv(text, "fuzz.csv");
  if (!parsed.ok()) {
    Check(parsed.status().message().find("fuzz.csv") != std::string::npos);
    return 0;
  }
  Check(!parsed->points.empty());
  for (const auto& p : parsed->points) {
    Check(std::isfinite(p.cmd.x()) && std::isfinite(p.cmd.y()));
    Check(std::isfinite(p.meas.x()) && std::isfinite(p.meas.y()));
    Check(std::isfinite(p.z_cmd_mm) && std::isfinite(p.t_s));
    Check(std::isfinite(p.v_mm_s.x()) && std::isfinite(p.v_mm_s.y()));
  }
  for (const auto& g : parsed->ReplicateGroups()) {
    Check(g.size() >= 2);
    for (int i : g) Check(i >= 0 && i < static_cast<int>(parsed->points.size()));
  }
  return 0;
}
