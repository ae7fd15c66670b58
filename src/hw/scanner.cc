#include "insitu/hw/scanner.h"

#include <cmath>
#include <string>

namespace insitu::hw {

Status TriggeredSweep::Validate() const {
  if (lines.empty()) return InvalidArgument("a triggered sweep needs at least one line");
  for (const auto& [from, to] : lines) {
    if (!from.allFinite() || !to.allFinite()) {
      return InvalidArgument("a triggered sweep's line has a non-finite point");
    }
  }
  if (!(speed_mm_per_s > 0 && std::isfinite(speed_mm_per_s))) {
    return InvalidArgument("sweep speed must be > 0 mm/s, got " + std::to_string(speed_mm_per_s));
  }
  if (!(settle_s >= 0 && std::isfinite(settle_s))) {
    return InvalidArgument("sweep settle time must be >= 0 s");
  }
  if (!(dwell_s > 0 && std::isfinite(dwell_s))) {
    return InvalidArgument("sweep dwell must be > 0 s, got " + std::to_string(dwell_s));
  }
  return Status::Ok();
}

}  // namespace insitu::hw
