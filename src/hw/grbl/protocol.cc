// GRBL 1.1's reply lines. The meanings are GRBL 1.1's error and alarm tables (the wiki's
// "Grbl v1.1 Error Codes" / "Alarm Codes") in short, so an operator reading our error knows what
// the controller complained about without its manual.
#include "hw/grbl/protocol.h"

#include <charconv>
#include <cmath>
#include <string>

namespace insitu::hw::grbl {
namespace {

bool StartsWith(std::string_view s, std::string_view prefix) {
  return s.substr(0, prefix.size()) == prefix;
}

// A whole-string integer; nullopt unless every character is part of it.
std::optional<int> ParseInt(std::string_view s) {
  int v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || s.empty()) return std::nullopt;
  return v;
}

std::optional<double> ParseDouble(std::string_view s) {
  double v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || s.empty()) return std::nullopt;
  // GRBL prints finite numbers of a few digits; nan, inf or a position beyond a kilometre is a
  // corrupted line, never a place to move to or from.
  if (!(std::abs(v) <= 1e6)) return std::nullopt;
  return v;
}

// "x,y,z" (one value per axis, at least one).
std::optional<std::vector<double>> ParseAxes(std::string_view s) {
  std::vector<double> out;
  for (;;) {
    const size_t comma = s.find(',');
    const auto v = ParseDouble(s.substr(0, comma));
    if (!v) return std::nullopt;
    out.push_back(*v);
    if (comma == std::string_view::npos) return out;
    s.remove_prefix(comma + 1);
  }
}

const char* ErrorText(int code) {
  switch (code) {
    case 1:
      return "a G-code word has no letter";
    case 2:
      return "a number is malformed or missing";
    case 3:
      return "the '$' system command is not recognised";
    case 4:
      return "a value that must be positive is negative";
    case 5:
      return "homing is not enabled in the settings ($22)";
    case 6:
      return "the step pulse must be longer than 3 us";
    case 7:
      return "the EEPROM read failed; settings were reset to defaults";
    case 8:
      return "this '$' command needs the controller Idle";
    case 9:
      return "G-code is locked out in the alarm or jog state";
    case 10:
      return "soft limits need homing enabled";
    case 11:
      return "the line is longer than the controller's line buffer";
    case 12:
      return "a '$' setting exceeds the maximum step rate";
    case 13:
      return "the safety door is open";
    case 14:
      return "the build info or startup line is longer than the EEPROM line";
    case 15:
      return "soft limit: the jog target exceeds the machine travel";
    case 16:
      return "a jog command has no '=' or holds forbidden G-code";
    case 17:
      return "laser mode needs a PWM output";
    case 20:
      return "unsupported or invalid G-code command";
    case 21:
      return "two G-code commands of the same modal group in one line";
    case 22:
      return "the feed rate is not set";
    case 23:
      return "the G-code command needs an integer value";
    case 24:
      return "two G-code commands in one line both need the axis words";
    case 25:
      return "a G-code word is repeated in the line";
    case 26:
      return "the G-code command needs axis words and has none";
    case 27:
      return "the line number is out of range";
    case 28:
      return "the G-code command lacks a required P or L word";
    case 29:
      return "only the work coordinate systems G54..G59 are supported";
    case 30:
      return "G53 needs G0 or G1 motion";
    case 31:
      return "axis words left unused while G80 motion cancel is active";
    case 32:
      return "an arc has no axis words in the selected plane";
    case 33:
      return "the motion target is invalid";
    case 34:
      return "an arc radius is invalid";
    case 35:
      return "an arc has no offset words in the selected plane";
    case 36:
      return "G-code words left unused in the line";
    case 37:
      return "the tool length offset is not on the tool length axis";
    case 38:
      return "the tool number exceeds the maximum";
    default:
      return nullptr;
  }
}

const char* AlarmText(int code) {
  switch (code) {
    case 1:
      return "hard limit triggered; the position is likely lost, re-home";
    case 2:
      return "soft limit: the motion target exceeds the machine travel; position kept";
    case 3:
      return "reset while in motion; the position is likely lost, re-home";
    case 4:
      return "probe fail: the probe was not in the expected state before the cycle";
    case 5:
      return "probe fail: the probe did not make contact within the travel";
    case 6:
      return "homing fail: the homing cycle was reset";
    case 7:
      return "homing fail: the safety door opened during homing";
    case 8:
      return "homing fail: pulling off did not clear the limit switch";
    case 9:
      return "homing fail: the limit switch was not found within the search distance";
    case 10:
      return "homing fail: the second limit switch of a dual axis was not found";
    default:
      return nullptr;
  }
}

}  // namespace

Line Classify(std::string_view line) {
  if (line == "ok") return {LineKind::kOk, -1};
  if (StartsWith(line, "error:")) return {LineKind::kError, ParseInt(line.substr(6)).value_or(-1)};
  if (StartsWith(line, "ALARM:")) return {LineKind::kAlarm, ParseInt(line.substr(6)).value_or(-1)};
  if (StartsWith(line, "<")) return {LineKind::kStatus, -1};
  if (StartsWith(line, "Grbl")) return {LineKind::kBanner, -1};
  if (StartsWith(line, "[")) return {LineKind::kMessage, -1};
  if (ParseSetting(line)) return {LineKind::kSetting, -1};
  return {LineKind::kOther, -1};
}

std::string DescribeError(int code) {
  const char* text = ErrorText(code);
  return "error:" + std::to_string(code) + " (" +
         (text ? text : "an error code GRBL 1.1 does not define") + ")";
}

std::string DescribeAlarm(int code) {
  const char* text = AlarmText(code);
  return "ALARM:" + std::to_string(code) + " (" +
         (text ? text : "an alarm code GRBL 1.1 does not define") + ")";
}

Result<StatusReport> ParseStatusReport(std::string_view line) {
  const std::string quoted = "status report '" + std::string(line) + "'";
  if (line.size() < 3 || line.front() != '<' || line.back() != '>') {
    return ParseError(quoted + " is not enclosed in <>");
  }
  std::string_view body = line.substr(1, line.size() - 2);
  StatusReport r;
  bool first = true;
  for (;;) {
    const size_t bar = body.find('|');
    const std::string_view field = body.substr(0, bar);
    if (first) {
      const size_t colon = field.find(':');
      r.state = std::string(field.substr(0, colon));
      static constexpr std::string_view kStates[] = {"Idle", "Run",   "Hold", "Jog",  "Alarm",
                                                     "Door", "Check", "Home", "Sleep"};
      bool known = false;
      for (const auto s : kStates) known = known || r.state == s;
      if (!known) return ParseError(quoted + " has an unknown state '" + r.state + "'");
      if (colon != std::string_view::npos) {
        const auto sub = ParseInt(field.substr(colon + 1));
        if (!sub) return ParseError(quoted + " has a malformed substate");
        r.substate = *sub;
      }
      first = false;
    } else {
      // Fields we use; the rest (FS, Bf, Ln, Pn, Ov, A) are skipped.
      const size_t colon = field.find(':');
      const std::string_view name = field.substr(0, colon);
      std::vector<double>* axes = name == "MPos"   ? &r.mpos
                                  : name == "WPos" ? &r.wpos
                                  : name == "WCO"  ? &r.wco
                                                   : nullptr;
      if (axes != nullptr) {
        const auto values =
            colon == std::string_view::npos ? std::nullopt : ParseAxes(field.substr(colon + 1));
        if (!values) return ParseError(quoted + " has a malformed " + std::string(name));
        *axes = *values;
      }
    }
    if (bar == std::string_view::npos) break;
    body.remove_prefix(bar + 1);
  }
  if (r.mpos.empty() && r.wpos.empty()) return ParseError(quoted + " has neither MPos nor WPos");
  return r;
}

std::string DescribeState(const StatusReport& r) {
  if (r.substate < 0) return r.state;
  const std::string name = r.state + ":" + std::to_string(r.substate);
  const char* meaning = nullptr;
  if (r.state == "Hold") {
    meaning =
        r.substate == 0 ? "feed hold complete, waiting for cycle start" : "feed hold in progress";
  } else if (r.state == "Door") {
    static constexpr const char* kDoor[] = {
        "safety door closed, waiting for cycle start", "safety door open, machine stopped",
        "safety door opened, retracting", "safety door closed, resuming"};
    if (r.substate <= 3) meaning = kDoor[r.substate];
  }
  return meaning ? name + " (" + meaning + ")" : name;
}

std::optional<std::pair<int, double>> ParseSetting(std::string_view line) {
  if (!StartsWith(line, "$")) return std::nullopt;
  const size_t eq = line.find('=');
  if (eq == std::string_view::npos) return std::nullopt;
  const auto n = ParseInt(line.substr(1, eq - 1));
  if (!n) return std::nullopt;
  const auto v = ParseDouble(line.substr(eq + 1));
  if (!v) return std::nullopt;
  return std::make_pair(*n, *v);
}

bool IsVersion11(std::string_view banner) {
  const size_t space = banner.find(' ');
  if (space == std::string_view::npos) return false;
  return StartsWith(banner.substr(space + 1), "1.1");
}

}  // namespace insitu::hw::grbl
