// GRBL 1.1's lines as the controller sends them (github.com/gnea/grbl/wiki, "Grbl v1.1
// Interface"): what each is, the status report's fields, and what the error and alarm codes
// mean. Pure functions over one line without its "\r\n"; nothing here touches the port.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::hw::grbl {

enum class LineKind {
  kOk,       // "ok": the line was executed (or, for a motion, planned)
  kError,    // "error:N": the line was refused
  kAlarm,    // "ALARM:N": the controller stopped and locked itself
  kStatus,   // "<Idle|MPos:...|...>": the answer to '?'
  kBanner,   // "Grbl 1.1h ['$' for help]": the controller (re)started
  kSetting,  // "$22=1": one line of "$$"
  kMessage,  // "[MSG:...]", "[GC:...]" and other bracketed feedback
  kOther,    // startup-line echoes (">G54:ok") and anything else
};

struct Line {
  LineKind kind = LineKind::kOther;
  int code = -1;  // N of error:N and ALARM:N (-1 when the number is malformed)
};

Line Classify(std::string_view line);

// "error:15 (jog target exceeds the machine travel)"; unknown codes say so.
std::string DescribeError(int code);
// "ALARM:1 (hard limit triggered: ...)"; unknown codes say so.
std::string DescribeAlarm(int code);

struct StatusReport {
  std::string state;  // Idle, Run, Hold, Jog, Alarm, Door, Check, Home, Sleep
  int substate = -1;  // Hold:N and Door:N; -1 when absent
  // Machine position, work position and work coordinate offset, one value per axis in the
  // controller's report unit (mm, or inch when $13=1); empty when the report has no such field.
  std::vector<double> mpos, wpos, wco;
};

// Parses a status report. Errors: parse_error naming what is malformed (no brackets, no state,
// an unknown state, a number that does not parse, neither MPos nor WPos).
Result<StatusReport> ParseStatusReport(std::string_view line);
// "Hold:0 (hold complete, ready to resume)", "Door:1 (safety door open)", "Alarm".
std::string DescribeState(const StatusReport& report);

// ($N, value) of a "$N=value" line; nullopt for anything else.
std::optional<std::pair<int, double>> ParseSetting(std::string_view line);
// The banner speaks the 1.1 protocol ("Grbl 1.1h", "GrblHAL 1.1f").
bool IsVersion11(std::string_view banner);

}  // namespace insitu::hw::grbl
