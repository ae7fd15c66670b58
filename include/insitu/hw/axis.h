// The motion that carries a line profiler over the part: a gantry's linear axes X, Y, Z and,
// where the machine has them, the rotary axes A (about X) and C (about Z) of seed 002's five-axis
// head. Positions are the machine's own (its axes' scales, its home), mm and degrees. An axis
// the machine does not have stays at 0 and refuses any other position.
#pragma once

#include <cstdint>
#include <string>

#include "insitu/core/status.h"

namespace insitu::hw {

struct AxisPose {
  double x_mm = 0.0, y_mm = 0.0, z_mm = 0.0;
  double a_deg = 0.0, c_deg = 0.0;
};

struct AxisInfo {
  std::string model;
  AxisPose min, max;                 // travel; min == max for an axis the machine lacks
  double speed_mm_per_s = 0.0;       // linear axes
  double encoder_counts_per_mm = 0;  // the encoder a profiler latches (the Y axis)
};

class Axis {
 public:
  Axis() = default;
  virtual ~Axis() = default;
  // An Axis owns a motion controller connection.
  Axis(const Axis&) = delete;
  Axis& operator=(const Axis&) = delete;

  virtual AxisInfo info() const = 0;
  // Where the axes are (their encoders).
  virtual Result<AxisPose> Position() const = 0;
  // Moves all axes together and waits until in position. Errors: out_of_range (outside the
  // travel, naming the axis), device_error (a fault or a move that does not arrive).
  virtual Status MoveTo(const AxisPose& pose) = 0;
};

// Why `pose` is outside `info`'s travel (naming the axis and its range), or OK.
Status CheckTravel(const AxisPose& pose, const AxisInfo& info);

}  // namespace insitu::hw
