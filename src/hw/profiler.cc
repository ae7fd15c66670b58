#include "insitu/hw/profiler.h"

#include <cmath>
#include <cstdio>
#include <string>

#include "insitu/hw/axis.h"

namespace insitu::hw {
namespace {

std::string Mm(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g mm", v);
  return b;
}

}  // namespace

int RangeProfile::valid_points() const {
  int n = 0;
  for (float z : z_mm) n += std::isfinite(z) ? 1 : 0;
  return n;
}

Status CheckProfile(const RangeProfile& p, const ProfilerInfo& info) {
  const std::string which = "profile " + std::to_string(p.sequence) + ": ";
  if (info.points > 0 && static_cast<int>(p.z_mm.size()) != info.points) {
    return Status(StatusCode::kDeviceError, which + std::to_string(p.z_mm.size()) +
                                                " points from a sensor of " +
                                                std::to_string(info.points));
  }
  if (!(p.x_spacing_mm > 0) || !std::isfinite(p.x_start_mm) ||
      (info.x_spacing_mm > 0 &&
       std::abs(p.x_spacing_mm - info.x_spacing_mm) > 1e-6 * info.x_spacing_mm)) {
    return Status(StatusCode::kDeviceError, which + "point spacing " + Mm(p.x_spacing_mm) +
                                                " is not the sensor's " + Mm(info.x_spacing_mm));
  }
  // A reading one count outside the range is the sensor rounding; more is a corrupt payload.
  const double slack = info.z_resolution_mm > 0 ? info.z_resolution_mm : 0.0;
  if (info.z_max_mm > info.z_min_mm) {
    for (size_t i = 0; i < p.z_mm.size(); ++i) {
      const float z = p.z_mm[i];
      if (std::isnan(z)) continue;
      if (!std::isfinite(z) || z < info.z_min_mm - slack || z > info.z_max_mm + slack) {
        return Status(StatusCode::kDeviceError,
                      which + "point " + std::to_string(i) + " reads " + Mm(z) +
                          ", outside the measuring range [" + Mm(info.z_min_mm) + ", " +
                          Mm(info.z_max_mm) + "]");
      }
    }
  }
  return Status::Ok();
}

Result<RangeProfile> Profiler::Grab() {
  INSITU_ASSIGN_OR_RETURN(RangeProfile p, GrabProfile());
  INSITU_RETURN_IF_ERROR(CheckProfile(p, info()));
  return p;
}

Status CheckTravel(const AxisPose& pose, const AxisInfo& info) {
  struct A {
    const char* name;
    double v, lo, hi;
    const char* unit;
  };
  const A axes[] = {{"x", pose.x_mm, info.min.x_mm, info.max.x_mm, "mm"},
                    {"y", pose.y_mm, info.min.y_mm, info.max.y_mm, "mm"},
                    {"z", pose.z_mm, info.min.z_mm, info.max.z_mm, "mm"},
                    {"a", pose.a_deg, info.min.a_deg, info.max.a_deg, "deg"},
                    {"c", pose.c_deg, info.min.c_deg, info.max.c_deg, "deg"}};
  for (const A& a : axes) {
    // A thousandth of a unit of slack: a position read back and sent again is not a fault.
    if (!std::isfinite(a.v) || a.v < a.lo - 1e-3 || a.v > a.hi + 1e-3) {
      char b[160];
      if (a.lo == a.hi) {
        std::snprintf(b, sizeof b, "axis %s: %.6g %s asked of a machine without that axis (fixed at %.6g)",
                      a.name, a.v, a.unit, a.lo);
      } else {
        std::snprintf(b, sizeof b, "axis %s: %.6g %s is outside its travel [%.6g, %.6g]", a.name,
                      a.v, a.unit, a.lo, a.hi);
      }
      return OutOfRange(b);
    }
  }
  return Status::Ok();
}

}  // namespace insitu::hw
