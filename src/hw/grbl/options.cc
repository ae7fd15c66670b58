// The GRBL stage's options (hw/grbl_options.h): checked without opening anything, so a job
// file's machine: section is read strictly before the port is touched.
#include "insitu/hw/grbl_options.h"

#include <cmath>
#include <string>
#include <string_view>

#include "hw/grbl/common.h"

namespace insitu::hw::grbl {
namespace {

struct Baud {
  int rate;
  speed_t constant;
};
constexpr Baud kBauds[] = {{9600, B9600},     {19200, B19200},   {38400, B38400},
                           {57600, B57600},   {115200, B115200}, {230400, B230400},
                           {460800, B460800}, {921600, B921600}};

}  // namespace

std::optional<speed_t> BaudConstant(int rate) {
  for (const Baud& b : kBauds) {
    if (b.rate == rate) return b.constant;
  }
  return std::nullopt;
}

Status StageOptions::Validate() const {
  if (port.empty()) return InvalidArgument("port must name the serial device, e.g. /dev/ttyUSB0");
  if (!BaudConstant(baud)) {
    return InvalidArgument(
        "baud must be one of 9600, 19200, 38400, 57600, 115200, 230400, "
        "460800, 921600 (got " +
        std::to_string(baud) + ")");
  }
  if (axis == '\0' || kAxes.find(axis) == std::string_view::npos) {
    return InvalidArgument("axis must be one of X, Y, Z, A, B, C");
  }
  if (!(std::isfinite(min_z_mm) && std::isfinite(max_z_mm) && min_z_mm < max_z_mm)) {
    return InvalidArgument(
        "min_z_mm must be < max_z_mm, both finite: the stage's travel in mm (got [" +
        Fixed(min_z_mm, 3) + ", " + Fixed(max_z_mm, 3) + "])");
  }
  if (!std::isfinite(machine_zero_mm)) return InvalidArgument("machine_zero_mm must be finite");
  if (direction != 1 && direction != -1) {
    return InvalidArgument("direction must be +1 (the controller's + is up) or -1 (got " +
                           std::to_string(direction) + ")");
  }
  if (!(feed_mm_per_min > 0 && feed_mm_per_min <= 100000)) {
    return InvalidArgument("feed_mm_per_min must be in (0, 100000]");
  }
  if (!(timeout_s > 0 && timeout_s <= 3600))
    return InvalidArgument("timeout_s must be in (0, 3600]");
  if (!(homing_timeout_s > 0 && homing_timeout_s <= 3600)) {
    return InvalidArgument("homing_timeout_s must be in (0, 3600]");
  }
  if (!(banner_wait_s >= 0 && banner_wait_s <= 60)) {
    return InvalidArgument("banner_wait_s must be in [0, 60]");
  }
  if (!(status_poll_s >= 0.001 && status_poll_s <= 10)) {
    return InvalidArgument("status_poll_s must be in [0.001, 10]");
  }
  if (!(position_tolerance_mm > 0 && position_tolerance_mm <= 10)) {
    return InvalidArgument("position_tolerance_mm must be in (0, 10]");
  }
  return Status::Ok();
}

}  // namespace insitu::hw::grbl
