// The 3D scan head as the job layer sees it, whatever drives it (simulator, SCANLAB RTC,
// BJJCZ LMC board). Positions are in the galvo frame, mm: x, y across the field, z the focus
// height (dynamic focus). Lists run on the head's clock; the marking laser can fire only while
// the head is armed (ros2_control-style: connected is not armed).
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <utility>
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
  // The head has an output wired to the side camera's trigger input (RunTriggeredSweep).
  bool trigger_output = false;
  // The field a correction table for this controller spans (an LMC board's lens: 65536
  // units), mm; 0: twice field_half_size_mm. And how its position words map onto the galvo
  // frame (an LMC board's swap_xy, flip_x, flip_y), which decides how a table is stored.
  double table_field_mm = 0.0;
  bool table_swap_xy = false, table_flip_x = false, table_flip_y = false;
};

// A scan as one run of the head, pacing the camera: for each line the pointer goes to the
// line's start, the mirrors settle for `settle_s`, the head pulses its trigger output (the
// camera exposes from that edge), and the pointer sweeps the line for `dwell_s` (at least the
// exposure) before the next line. Positions in the galvo frame, mm.
struct TriggeredSweep {
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> lines;  // from, to
  double speed_mm_per_s = 500.0;
  double settle_s = 0.02;
  double dwell_s = 0.05;

  // Errors: invalid_argument (no lines, speed <= 0, a negative or non-finite time).
  Status Validate() const;
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

  // Runs `sweep` on the head's clock, pulsing the trigger output once per line, and returns
  // when the last line's dwell has passed (the pointer is then off). control.abort stops it
  // between pulses (cancelled); control.progress gets the fraction of lines done.
  // Errors: failed_precondition (the head has no trigger output), out_of_range (a line
  // outside the field or focus range), invalid_argument (TriggeredSweep::Validate),
  // device_error.
  Status RunTriggeredSweep(const TriggeredSweep& sweep, const ListControl& control = {}) {
    if (!info().trigger_output) {
      return FailedPrecondition("the scan head has no trigger output for the camera");
    }
    INSITU_RETURN_IF_ERROR(sweep.Validate());
    if (control.abort != nullptr && control.abort->load()) {
      return Status(StatusCode::kCancelled, "sweep aborted before it started");
    }
    return RunSweep(sweep, control);
  }

  // What the controller drives the galvos with for a command, as the command of the same head
  // driven linearly (galvo frame, mm: the optical angles times the design focal length), when
  // the controller's correction is a table this backend holds (an LMC board: the table it
  // uploaded, none the identity). False when the head corrects itself (its own design
  // correction: the simulated head, a digital head): the caller then takes the head's design
  // from its calibration. So a correction measured through the head can be composed with what
  // the controller does now (field_calibration's field.cor).
  virtual bool DriveCommand(const Eigen::Vector2d& command_mm, Eigen::Vector2d* drive_mm) const {
    (void)command_mm;
    (void)drive_mm;
    return false;
  }
  // The last list ExecuteList sent, as the controller received it, one command a line in the
  // controller's own terms (an LMC board: its list commands up to the end-of-list, as
  // `insitu lmc decode` prints a capture of them); empty when the controller takes the galvo
  // list as insitu emits it (the mark job's galvo_list.txt is then that).
  virtual std::string ReceivedList() const { return {}; }
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
  // The backend's triggered sweep (a head whose info() has trigger_output). The sweep is
  // valid and not aborted yet.
  virtual Status RunSweep(const TriggeredSweep& sweep, const ListControl& control) {
    (void)sweep;
    (void)control;
    return FailedPrecondition("the scan head has no trigger output for the camera");
  }
};

}  // namespace insitu::hw
