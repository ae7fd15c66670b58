// The Z stage under the part (height calibration moves it; scans leave it still). mm, up +.
#pragma once

#include "insitu/core/status.h"

namespace insitu::hw {

class Stage {
 public:
  Stage() = default;
  virtual ~Stage() = default;
  // A Stage owns a motion controller connection.
  Stage(const Stage&) = delete;
  Stage& operator=(const Stage&) = delete;

  virtual double min_z_mm() const = 0;
  virtual double max_z_mm() const = 0;
  virtual Result<double> Position() const = 0;
  // Moves and waits until in position. Errors: out_of_range (outside travel).
  virtual Status MoveTo(double z_mm) = 0;
};

}  // namespace insitu::hw
