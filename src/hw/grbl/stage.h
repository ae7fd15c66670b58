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
//
// Private to src/hw (the backend's folder, machine.cc and its tests); the options a job sets are
// in insitu/hw/grbl_options.h, the lines of the protocol in protocol.h.
#pragma once

#include <memory>

#include "insitu/core/status.h"
#include "insitu/hw/grbl_options.h"
#include "insitu/hw/stage.h"

namespace insitu::hw::grbl {

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
