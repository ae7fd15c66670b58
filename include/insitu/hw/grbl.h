// A Z stage on a GRBL 1.1 motion controller over a serial port (lab Z stages and small CNC
// controllers): the Stage of hw/stage.h, its numbers in the cell's frame (mm, up +).
//
// Protocol (GRBL 1.1, github.com/gnea/grbl/wiki): lines go out one at a time and each is
// answered by "ok" or "error:N"; "ALARM:N", "[MSG:...]" and the banner ("Grbl 1.1h ['$' for
// help]") may come at any time; the real-time byte '?' is answered by a status report
// "<State|MPos:x,y,z|...>" (or WPos, with the work offset WCO sent every few reports), 0x18 is
// a soft reset. Moves go out in machine coordinates (G53), so the controller's work offsets
// (G54, G92) never shift the stage.
//
// Frames: the cell's z (this interface) and the controller's machine coordinate of the axis are
// related by machine = machine_zero_mm + direction * z.
#pragma once

#include <memory>
#include <string>

#include "insitu/core/status.h"
#include "insitu/hw/stage.h"

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

// Opens the port (raw 8N1, exclusive), waits for or provokes the GRBL 1.1 banner, reads the
// settings ($$), homes when home_on_open, and returns an Idle stage.
// Errors: invalid_argument (options), not_found (no such port), device_error (the port cannot
// be opened or is held by another program, no banner or reply within the deadline, not GRBL
// 1.1, homing failed: names the alarm), failed_precondition (the controller is in ALARM and
// home_on_open is false; home_on_open with homing disabled on the controller, $22=0).
//
// The stage's calls (single-threaded use; each bounded by its deadline, never blocking for
// good): MoveTo checks the travel (out_of_range), sends "G21 G90 G53 G1 <axis><machine> F<feed>"
// and "G4 P0" (answered once the motion is done), polls '?' meanwhile and then checks the
// reported position within position_tolerance_mm. Position() is a status query (and fails while
// the controller is in ALARM: its position is not trustworthy until it homes). Errors of
// both are device_error naming the port and: "error:N" with its meaning, "ALARM:N" with its
// meaning, a state that cannot move (Alarm, Hold, Door, ...), "no reply" after the deadline, or
// "lost the serial port <port>: <reason>" (unplugged, hung up, write failed); after a lost port
// every call fails at once with that same status.
Result<std::unique_ptr<Stage>> OpenStage(const StageOptions& options);

}  // namespace insitu::hw::grbl
