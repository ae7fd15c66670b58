// What a job's `machine:` section sets for a Z stage on a GRBL 1.1 motion controller (stage:
// grbl, its `grbl:` part): the serial port, the axis and the stage's travel. The stage itself
// (the serial port and the GRBL conversation) stays in src/hw/grbl.
//
// Frames: the cell's z (hw/stage.h: mm, up +) and the controller's machine coordinate of the
// axis are related by machine = machine_zero_mm + direction * z.
#pragma once

#include <string>

#include "insitu/core/status.h"

namespace insitu::hw::grbl {

struct StageOptions {
  std::string port;   // the serial device, e.g. /dev/ttyUSB0 or /dev/serial/by-id/...
  int baud = 115200;  // 9600, 19200, 38400, 57600, 115200, 230400, 460800 or 921600; 8N1, raw
  char axis = 'Z';    // the controller's axis that moves the stage: X, Y, Z, A, B or C
  // The stage's travel in the cell's frame, mm, up +; MoveTo refuses targets outside it before
  // anything is sent. No default (it is the stage's): Validate wants min_z_mm < max_z_mm. Keep it
  // inside the controller's own soft limits (after homing, GRBL's machine travel on an axis
  // that homes to + is [-max travel, 0], the max travel being $130..$132).
  double min_z_mm = 0.0;
  double max_z_mm = 0.0;
  double machine_zero_mm = 0.0;  // the cell's z = 0 in the controller's machine coordinates, mm
  int direction = +1;            // +1: the controller's + is up in the cell; -1: it is down
  // Home ($H) when the port opens: a controller with homing enabled ($22=1) starts in ALARM
  // and only homing gives it a trustworthy position. false: the stage must already be homed
  // (or have homing disabled); OpenStage refuses a controller in ALARM.
  bool home_on_open = true;
  double feed_mm_per_min = 300.0;  // G1 feed of every move (GRBL's unit), > 0
  // Deadline of a reply (any line's "ok", a status report), s. A move gets this plus its own
  // time at the feed rate, so a long slow move is not cut short.
  double timeout_s = 5.0;
  double homing_timeout_s = 60.0;  // deadline of the homing cycle ($H), s
  // After the port opens: how long to wait for the banner an Arduino GRBL prints when opening
  // the port resets it (DTR), s; none by then and a soft reset (0x18) provokes one.
  double banner_wait_s = 2.5;
  double status_poll_s = 0.1;  // '?' period while a move runs (GRBL takes up to ~10 Hz), s
  // How far the reported position may be from the target once the controller is Idle, mm.
  double position_tolerance_mm = 0.01;

  // invalid_argument naming the field and what it must be.
  Status Validate() const;
};

}  // namespace insitu::hw::grbl
