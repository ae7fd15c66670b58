// The 3D scan head as the job layer sees it, whatever drives it (simulator, SCANLAB RTC,
// BJJCZ LMC board). Positions are in the galvo frame, mm: x, y across the field, z the focus
// height (dynamic focus). Lists run on the head's clock; the marking laser can fire only while
// the head is armed (ros2_control-style: connected is not armed).
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::hw {

struct GalvoListEntry {
  enum class Kind { kJump, kMark };
  Kind kind = Kind::kJump;
  Eigen::Vector3d to_in_galvo = Eigen::Vector3d::Zero();  // mm
};

// A list of 3D jumps and marks with the speeds to run it at.
struct GalvoList {
  std::vector<GalvoListEntry> entries;
  double jump_speed_mm_per_s = 5000.0;
  double mark_speed_mm_per_s = 1000.0;
  double laser_power = 0.5;             // fraction of full power
  double laser_frequency_khz = 30.0;    // pulse repetition rate
  double laser_on_delay_us = 0.0, laser_off_delay_us = 0.0;
  double jump_delay_us = 0.0, mark_delay_us = 0.0;

  // Whether any entry fires the marking laser.
  bool HasMarks() const {
    for (const GalvoListEntry& e : entries) {
      if (e.kind == GalvoListEntry::Kind::kMark) return true;
    }
    return false;
  }
};

struct ScannerInfo {
  std::string model;
  double field_half_size_mm = 0.0;  // commands beyond +-this are refused
  double focus_range_mm = 0.0;      // dynamic focus +-
  double clock_us = 10.0;
};

// How a running list is stopped, and what it tells while it runs.
struct ListControl {
  // Polled by the head while the list runs: on every list tick (simulator), on every status
  // poll (a board streaming the list). Once true the laser goes off at once, the list is
  // aborted and ExecuteList returns cancelled.
  const std::atomic<bool>* abort = nullptr;
  // Called on the executing thread with the fraction of the list's time done, about every
  // 100 ms of list time and once at the end.
  std::function<void(double fraction)> progress;
};

class Scanner {
 public:
  Scanner() = default;
  virtual ~Scanner() = default;
  // A Scanner owns a device connection; copies would fight over it.
  Scanner(const Scanner&) = delete;
  Scanner& operator=(const Scanner&) = delete;

  virtual ScannerInfo info() const = 0;

  // Sweeps the (eye-safe) pointer back and forth along a straight line until stopped.
  // Errors: out_of_range (outside field or focus range), invalid_argument (speed <= 0).
  virtual Status StartPointerLine(const Eigen::Vector3d& from_in_galvo,
                                  const Eigen::Vector3d& to_in_galvo, double speed_mm_per_s) = 0;
  virtual Status StopPointer() = 0;

  // Arming enables the marking laser for ExecuteList; disarm when the job ends or fails.
  virtual Status Arm() = 0;
  virtual Status Disarm() = 0;
  virtual bool armed() const = 0;
  // Runs a list to completion or until aborted; marks fire the marking laser. Errors:
  // failed_precondition (not armed and the list marks), out_of_range (a point outside the
  // field), cancelled (aborted through control.abort: the laser is off, the head stopped where
  // it was, the list's remainder not run).
  // Both preconditions are checked here, once for every backend.
  Status ExecuteList(const GalvoList& list, const ListControl& control = {}) {
    if (control.abort != nullptr && control.abort->load()) {
      return Status(StatusCode::kCancelled, "list aborted before it started");
    }
    if (list.HasMarks() && !armed()) {
      return FailedPrecondition("the list marks but the scan head is not armed");
    }
    return RunList(list, control);
  }

 protected:
  // The backend's list execution. ExecuteList has checked the abort flag once, and that a list
  // which marks runs only on an armed head.
  virtual Status RunList(const GalvoList& list, const ListControl& control) = 0;
};

}  // namespace insitu::hw
