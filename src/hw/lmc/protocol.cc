#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <thread>

#include "hw/lmc/lmc.h"

namespace insitu::hw::lmc {
namespace {

constexpr double kUnits = 65536.0;

void Put(std::vector<uint8_t>* out, uint16_t w) {
  out->push_back(static_cast<uint8_t>(w & 0xFF));
  out->push_back(static_cast<uint8_t>(w >> 8));
}

// |us| as a delay word, and the sign word the board takes after it (0x8000 when negative).
Command Delay(uint16_t op, double us) {
  const double magnitude = std::min(std::round(std::abs(us)), 65535.0);
  return {op, static_cast<uint16_t>(magnitude), static_cast<uint16_t>(us < 0 ? 0x8000 : 0), 0, 0,
          0};
}

// Truncated, as the reference list's distances are.
uint16_t Distance(const std::array<uint16_t, 2>& a, const std::array<uint16_t, 2>& b) {
  const double d = std::hypot(static_cast<double>(a[0]) - b[0], static_cast<double>(a[1]) - b[1]);
  return static_cast<uint16_t>(std::min(std::floor(d), 65535.0));
}

// The source's power and pulse-rate commands (Source, insitu/hw/lmc_options.h), in the order
// EzCad sends them: the rate first.
Status AppendLaser(const GalvoList& list, const BoardOptions& o, std::vector<Command>* out) {
  const double khz = list.laser_frequency_khz;
  const double percent = 100.0 * list.laser_power;
  const auto word = [](double v) { return static_cast<uint16_t>(std::round(v)); };
  switch (o.source) {
    case Source::kFiber:
    case Source::kMopa:
      // The Q-switch period in 50 ns units.
      if (!(khz >= 20000.0 / 65535.0 && khz <= 20000.0)) {
        return InvalidArgument("pulse rate " + std::to_string(khz) +
                               " kHz is outside a fibre source's [0.31, 20000] kHz (the "
                               "Q-switch period word)");
      }
      if (o.source == Source::kMopa) {
        out->push_back({kFiberPulseWidth, word(o.pulse_width_ns), 0, 0, 0, 0});
      }
      out->push_back({kQSwitchPeriod, word(20000.0 / khz), 0, 0, 0, 0});
      out->push_back({kMarkCurrent, word(list.laser_power * 0xFFF), 0, 0, 0, 0});
      return Status::Ok();
    case Source::kCo2:
    case Source::kUv: {
      // The pulse period in 100 ns units, the first pulse killer and the duty (power ratio)
      // as the period's share in its own scale.
      if (!(khz >= 10000.0 / 65535.0 && khz <= 10000.0)) {
        return InvalidArgument("pulse rate " + std::to_string(khz) + " kHz is outside a " +
                               SourceName(o.source) +
                               " source's [0.16, 10000] kHz (the mark frequency word)");
      }
      const double power = o.power_invert ? 100.0 - percent : percent;
      if (200.0 * power / khz > 65535.0) {
        return InvalidArgument("power " + std::to_string(percent) + " % at " + std::to_string(khz) +
                               " kHz overflows the power ratio word");
      }
      out->push_back({kMarkFreq, word(10000.0 / khz), 0, 0, 0, 0});
      const uint16_t fpk = word(2000.0 / khz);
      out->push_back({kSetCo2Fpk, fpk, fpk, 0, 0, 0});
      out->push_back({kMarkPowerRatio, word(200.0 * power / khz), 0, 0, 0, 0});
      return Status::Ok();
    }
  }
  return InvalidArgument("unknown laser source");
}

}  // namespace

std::vector<uint8_t> GotoXY(const std::array<uint16_t, 2>& from,
                            const std::array<uint16_t, 2>& to) {
  return SingleCommand(kGotoXY, to[0], to[1], 0, Distance(from, to));
}

const char* SourceName(Source s) {
  switch (s) {
    case Source::kFiber:
      return "fiber";
    case Source::kMopa:
      return "mopa";
    case Source::kCo2:
      return "co2";
    case Source::kUv:
      return "uv";
  }
  return "?";
}

Status UsbSelector::Validate() const {
  if (timeout_ms < 1 || timeout_ms > 10000) return InvalidArgument("timeout_ms must be in 1..10000");
  if (retries < 0 || retries > 10) return InvalidArgument("retries must be in 0..10");
  if (bus < -1 || address < -1) return InvalidArgument("bus and address must be >= 0 (or -1: any)");
  return Status::Ok();
}

Status BoardOptions::Validate() const {
  if (!(lens_mm > 1.0 && lens_mm < 2000.0)) return InvalidArgument("lens_mm must be in (1, 2000)");
  if (focus == Focus::kDaZWord) {
    if (!(z_units_per_mm > 0))
      return InvalidArgument("z_units_per_mm must be > 0 with a focus shifter");
    if (!(focus_range_mm > 0))
      return InvalidArgument("focus_range_mm must be > 0 with a focus shifter");
    if (focus_range_mm * z_units_per_mm > 32767.0) {
      return InvalidArgument("focus_range_mm * z_units_per_mm exceeds the Z word's +-32767");
    }
  }
  if (!(open_mo_delay_us >= 0 && open_mo_delay_us <= 655350)) {
    return InvalidArgument("open_mo_delay_us must be in [0, 655350]");
  }
  if (!(polygon_delay_us >= 0 && polygon_delay_us <= 65535)) {
    return InvalidArgument("polygon_delay_us must be in [0, 65535]");
  }
  if (poll_ms < 1 || poll_ms > 1000) return InvalidArgument("poll_ms must be in 1..1000");
  if (!(list_timeout_s >= 0)) return InvalidArgument("list_timeout_s must be >= 0 (0: none)");
  if (source == Source::kMopa) {
    if (!(pulse_width_ns >= 1 && pulse_width_ns <= 65535)) {
      return InvalidArgument("pulse_width_ns must be in [1, 65535] ns for a mopa source, got " +
                             std::to_string(pulse_width_ns));
    }
  } else if (pulse_width_ns != 0) {
    return InvalidArgument(std::string("pulse_width_ns means nothing to a ") + SourceName(source) +
                           " source (only mopa has one)");
  }
  if (power_invert && source != Source::kUv) {
    return InvalidArgument(std::string("power_invert means nothing to a ") + SourceName(source) +
                           " source (only uv)");
  }
  if (packets_before_start < 1) return InvalidArgument("packets_before_start must be >= 1");
  if (trigger_port != 0) {
    if ((trigger_port & (trigger_port - 1)) != 0) {
      return InvalidArgument("trigger_port must be one output bit (0x0001..0x8000), or 0: none");
    }
    if ((trigger_port & (pointer_port | list_ports)) != 0) {
      return InvalidArgument("trigger_port must be a bit of its own, not the pointer's "
                             "(pointer_port) or a marking list's (list_ports)");
    }
    // The pointer waits at the line's start while the pulse is high: 1 ms at most.
    if (!(trigger_pulse_us >= 10 && trigger_pulse_us <= 1000)) {
      return InvalidArgument("trigger_pulse_us must be in [10, 1000]");
    }
  }
  return Status::Ok();
}

// Truncation (floor), not rounding: the reference list the encoder is checked against
// (docs/hardware.md) truncates; it biases points by at most one unit (1.7 um on a 110 mm lens).
Result<std::array<uint16_t, 2>> ToUnits(double x_mm, double y_mm, const BoardOptions& o) {
  const Eigen::Vector2d w = BoardWordsOf(Eigen::Vector2d(x_mm, y_mm), o);
  const double u = std::floor(w.x()), v = std::floor(w.y());
  if (!(u >= 0 && u <= 65535 && v >= 0 && v <= 65535)) {
    char text[160];
    std::snprintf(text, sizeof text,
                  "point (%.3f, %.3f) mm is outside the %.1f mm lens field of the board", x_mm,
                  y_mm, o.lens_mm);
    return OutOfRange(text);
  }
  return std::array<uint16_t, 2>{static_cast<uint16_t>(u), static_cast<uint16_t>(v)};
}

std::array<double, 2> FromUnits(uint16_t u, uint16_t v, const BoardOptions& o) {
  const Eigen::Vector2d p = GalvoMmOf(Eigen::Vector2d(u, v), o);
  return {p.x(), p.y()};
}

std::array<double, 2> ApplyBoardTable(const BoardCorrection& table, double word1, double word2) {
  if (table.offsets.size() != 65 * 65) return {word1, word2};
  // Node index along each word, clamped to the table: beyond its edge the edge's error.
  const auto at = [](double w, int* k, double* t) {
    const double u = std::clamp(w / 1024.0, 0.0, 64.0);
    *k = std::min(63, static_cast<int>(std::floor(u)));
    *t = u - *k;
  };
  int i, j;
  double ti, tj;
  at(word1, &i, &ti);  // inner: word 1
  at(word2, &j, &tj);  // outer: word 2
  const auto node = [&](int inner, int outer) { return table.offsets[outer * 65 + inner]; };
  std::array<double, 2> e{};
  for (int c = 0; c < 2; ++c) {
    e[c] = (1 - ti) * (1 - tj) * node(i, j)[c] + ti * (1 - tj) * node(i + 1, j)[c] +
           (1 - ti) * tj * node(i, j + 1)[c] + ti * tj * node(i + 1, j + 1)[c];
  }
  return {word1 - e[0], word2 - e[1]};
}

Eigen::Vector2d ApplyBoardTableMm(const BoardCorrection& table, const BoardOptions& o,
                                  const Eigen::Vector2d& command_mm) {
  const Eigen::Vector2d w = BoardWordsOf(command_mm, o);
  const auto sent = ApplyBoardTable(table, w.x(), w.y());
  return GalvoMmOf(Eigen::Vector2d(sent[0], sent[1]), o);
}

// One JumpTo or MarkTo to `p` (galvo frame, mm) from `*position`, preceded by the Z DA word
// when the focus changes. Errors: out_of_range (outside the field or the focus range, z on a
// head without focus).
static Status AppendPoint(const Eigen::Vector3d& p, bool mark, const BoardOptions& o,
                          std::array<uint16_t, 2>* position, uint16_t* z_word,
                          std::vector<Command>* out) {
  INSITU_ASSIGN_OR_RETURN(const auto units, ToUnits(p.x(), p.y(), o));
  if (o.focus == Focus::kNone) {
    if (p.z() != 0.0) {
      return OutOfRange("z = " + std::to_string(p.z()) +
                        " mm, but this LMC head has no focus shifter (focus: none)");
    }
  } else {
    if (std::abs(p.z()) > o.focus_range_mm) {
      return OutOfRange("z = " + std::to_string(p.z()) + " mm is outside the focus range +-" +
                        std::to_string(o.focus_range_mm) + " mm");
    }
    const auto z = static_cast<uint16_t>(std::floor(32768.0 + p.z() * o.z_units_per_mm));
    if (z != *z_word) {
      out->push_back({kSetDaZWord, z, 0, 0, 0, 0});
      *z_word = z;
    }
  }
  out->push_back({mark ? kMarkTo : kJumpTo, units[0], units[1], 0, Distance(*position, units), 0});
  *position = units;
  return Status::Ok();
}

Result<std::vector<Command>> EncodeList(const GalvoList& list, const BoardOptions& o,
                                        std::array<uint16_t, 2>* position, uint16_t* z_word) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  if (!(list.jump_speed_mm_per_s > 0 && list.mark_speed_mm_per_s > 0)) {
    return InvalidArgument("list speeds must be > 0");
  }
  if (!(list.laser_power >= 0 && list.laser_power <= 1)) {
    return InvalidArgument("laser power must be a fraction in [0, 1]");
  }
  const double per_ms = kUnits / o.lens_mm / 1000.0;  // units per ms at 1 mm/s
  const auto speed = [&](double mm_per_s) {
    // Truncated, as the reference list does; at least one unit per ms.
    return static_cast<uint16_t>(std::clamp(std::floor(mm_per_s * per_ms), 1.0, 65535.0));
  };
  std::vector<Command> out;
  out.push_back({kReadyMark, 0, 0, 0, 0, 0});
  out.push_back(
      {kDelayTime, static_cast<uint16_t>(std::round(o.open_mo_delay_us / 10.0)), 0, 0, 0, 0});
  out.push_back({kWritePortList, o.list_ports, 0, 0, 0, 0});
  out.push_back({kJumpSpeed, speed(list.jump_speed_mm_per_s), 0, 0, 0, 0});
  INSITU_RETURN_IF_ERROR(AppendLaser(list, o, &out));
  out.push_back({kMarkSpeed, speed(list.mark_speed_mm_per_s), 0, 0, 0, 0});
  out.push_back(Delay(kLaserOnDelay, list.laser_on_delay_us));
  out.push_back(Delay(kLaserOffDelay, list.laser_off_delay_us));
  // The polygon delay in 10 us units (the reference list's 0x000a for 100 us).
  out.push_back({kPolygonDelay, static_cast<uint16_t>(std::round(o.polygon_delay_us / 10.0)), 0,
                 0, 0, 0});

  const auto& entries = list.entries;
  // The jump delay is a list parameter, as the laser delays are: the board waits it after
  // every jump from where it is set on. Set once, before the first jump.
  bool jump_delay_set = false;
  for (size_t i = 0; i < entries.size(); ++i) {
    const GalvoListEntry& e = entries[i];
    const bool mark = e.kind == GalvoListEntry::Kind::kMark;
    if (!mark && !jump_delay_set && list.jump_delay_us > 0) {
      out.push_back(Delay(kJumpDelay, list.jump_delay_us));
      jump_delay_set = true;
    }
    INSITU_RETURN_IF_ERROR(AppendPoint(e.to_in_galvo, mark, o, position, z_word, &out));
    const bool sequence_ends =
        mark && (i + 1 == entries.size() || entries[i + 1].kind != GalvoListEntry::Kind::kMark);
    if (sequence_ends && list.mark_delay_us > 0) {
      out.push_back(
          {kDelayTime,
           static_cast<uint16_t>(std::min(std::round(list.mark_delay_us / 10.0), 65535.0)), 0, 0, 0,
           0});
    }
  }
  return out;
}

Result<std::vector<Command>> EncodeTriggeredSweep(const TriggeredSweep& sweep,
                                                  const BoardOptions& o,
                                                  std::array<uint16_t, 2>* position,
                                                  uint16_t* z_word) {
  INSITU_RETURN_IF_ERROR(sweep.Validate());
  if (o.trigger_port == 0) {
    return FailedPrecondition("the board has no output wired to the camera (trigger_port)");
  }
  // The settle as a list delay (10 us units, up to 655.35 ms).
  const double settle_units = std::round(sweep.settle_s * 1e5);
  if (settle_units > 65535.0) {
    return OutOfRange("settle " + std::to_string(sweep.settle_s * 1e3) +
                      " ms is longer than the board's list delay (655.35 ms)");
  }
  // The light list's parameters: the pointer port on, the laser off, the sweep's speed.
  GalvoList light;
  light.jump_speed_mm_per_s = sweep.speed_mm_per_s;
  light.laser_power = 0.0;
  BoardOptions lo = o;
  lo.list_ports = o.pointer_port;
  lo.open_mo_delay_us = 0.0;
  INSITU_ASSIGN_OR_RETURN(std::vector<Command> out, EncodeList(light, lo, position, z_word));
  const auto pulse = static_cast<uint16_t>(std::round(o.trigger_pulse_us / 10.0));
  const double scale = kUnits / o.lens_mm;  // units per mm
  for (const auto& [a, b] : sweep.lines) {
    // Each line from its end nearer to where the head is: the jump between lines is then
    // about one line spacing, not a line's length (the exposure sees the line either way).
    const auto ua = ToUnits(a.x(), a.y(), o), ub = ToUnits(b.x(), b.y(), o);
    bool reverse = false;
    if (ua.ok() && ub.ok()) {
      reverse = Distance(*position, *ub) < Distance(*position, *ua);
    }
    const Eigen::Vector3d& from = reverse ? b : a;
    const Eigen::Vector3d& to = reverse ? a : b;
    INSITU_RETURN_IF_ERROR(AppendPoint(from, /*mark=*/false, o, position, z_word, &out));
    if (settle_units > 0) {
      out.push_back({kDelayTime, static_cast<uint16_t>(settle_units), 0, 0, 0, 0});
    }
    out.push_back({kWritePortList, static_cast<uint16_t>(o.pointer_port | o.trigger_port), 0, 0,
                   0, 0});
    out.push_back({kDelayTime, pulse, 0, 0, 0, 0});
    out.push_back({kWritePortList, o.pointer_port, 0, 0, 0, 0});
    // Back and forth along the line for the dwell, the last pass ending where the dwell does
    // (the next line starts from there).
    const double length = (to - from).norm();
    double left_mm = sweep.dwell_s * sweep.speed_mm_per_s;
    if (length * scale < 1.0) {  // a point: stay on it
      out.push_back({kDelayTime,
                     static_cast<uint16_t>(std::min(std::round(sweep.dwell_s * 1e5), 65535.0)), 0,
                     0, 0, 0});
      continue;
    }
    for (int k = 1; left_mm > 0; ++k) {
      const Eigen::Vector3d& end = k % 2 ? to : from;
      const Eigen::Vector3d& start = k % 2 ? from : to;
      const double step = std::min(left_mm, length);
      INSITU_RETURN_IF_ERROR(AppendPoint(start + (end - start) * (step / length), false, o,
                                         position, z_word, &out));
      left_mm -= step;
    }
  }
  return out;
}

std::vector<std::vector<uint8_t>> Packets(const std::vector<Command>& commands) {
  // The list, then its end-of-list (the board runs a list until it meets one: a list filling
  // its last packet exactly would run on into whatever the board's list memory holds), then
  // the last packet's padding.
  const bool ends = !commands.empty() && commands.back()[0] == kEndOfList;
  const size_t total = commands.size() + (ends ? 0 : 1);
  std::vector<std::vector<uint8_t>> packets;
  for (size_t first = 0; first < total; first += kPacketCommands) {
    std::vector<uint8_t> packet;
    packet.reserve(kPacketBytes);
    for (size_t k = 0; k < kPacketCommands; ++k) {
      const Command c =
          first + k < commands.size() ? commands[first + k] : Command{kEndOfList, 0, 0, 0, 0, 0};
      for (uint16_t w : c) Put(&packet, w);
    }
    packets.push_back(std::move(packet));
  }
  return packets;
}

std::vector<uint8_t> SingleCommand(uint16_t op, uint16_t p1, uint16_t p2, uint16_t p3, uint16_t p4,
                                   uint16_t p5) {
  std::vector<uint8_t> out;
  out.reserve(kCommandBytes);
  for (uint16_t w : {op, p1, p2, p3, p4, p5}) Put(&out, w);
  return out;
}

Command DecodeCommand(const uint8_t* b) {
  Command c{};
  for (size_t i = 0; i < c.size(); ++i)
    c[i] = static_cast<uint16_t>(b[2 * i] | (b[2 * i + 1] << 8));
  return c;
}

std::string FormatCommands(const std::vector<Command>& commands) {
  static const std::map<uint16_t, const char*> kNames = {
      {kJumpTo, "listJumpTo"},
      {kEndOfList, "listEndOfList"},
      {kDelayTime, "listDelayTime"},
      {kMarkTo, "listMarkTo"},
      {kJumpSpeed, "listJumpSpeed"},
      {kLaserOnDelay, "listLaserOnDelay"},
      {kLaserOffDelay, "listLaserOffDelay"},
      {kMarkSpeed, "listMarkSpeed"},
      {kJumpDelay, "listJumpDelay"},
      {kPolygonDelay, "listPolygonDelay"},
      {kWritePortList, "listWritePort"},
      {kMarkCurrent, "listMarkCurrent"},
      {kQSwitchPeriod, "listQSwitchPeriod"},
      {kSetDaZWord, "listSetDaZWord"},
      {kMarkFreq, "listMarkFreq"},
      {kMarkPowerRatio, "listMarkPowerRatio"},
      {kSetCo2Fpk, "listSetCo2FPK"},
      {kFiberPulseWidth, "listFiberYLPMPulseWidth"},
      {kReadyMark, "listReadyMark"}};
  std::string out;
  for (const Command& c : commands) {
    const auto it = kNames.find(c[0]);
    char line[96];
    if (it != kNames.end()) {
      std::snprintf(line, sizeof line, "%-20s %04x %04x %04x %04x %04x\n", it->second, c[1], c[2],
                    c[3], c[4], c[5]);
    } else {
      std::snprintf(line, sizeof line, "op %04x               %04x %04x %04x %04x %04x\n", c[0],
                    c[1], c[2], c[3], c[4], c[5]);
    }
    out += line;
  }
  return out;
}

Result<std::vector<std::vector<uint8_t>>> CorrectionUpload(const BoardCorrection& table) {
  if (table.offsets.size() != 65 * 65) {
    return InvalidArgument("a board correction table has 65 x 65 = 4225 nodes, not " +
                           std::to_string(table.offsets.size()));
  }
  const auto word = [](int32_t v) -> Result<uint16_t> {
    if (v <= -0x8000 || v >= 0x8000) {
      return OutOfRange("correction offset " + std::to_string(v) + " units is beyond +-32767");
    }
    // Sign-magnitude: a negative offset is sent as |v| + 0x8000.
    return static_cast<uint16_t>(v < 0 ? -v + 0x8000 : v);
  };
  std::vector<std::vector<uint8_t>> out{SingleCommand(kWriteCorTable, 1)};
  out.reserve(1 + table.offsets.size());
  for (size_t i = 0; i < table.offsets.size(); ++i) {
    INSITU_ASSIGN_OR_RETURN(const uint16_t dx, word(table.offsets[i][0]));
    INSITU_ASSIGN_OR_RETURN(const uint16_t dy, word(table.offsets[i][1]));
    out.push_back(SingleCommand(kWriteCorLine, dx, dy, i == 0 ? 0 : 1));
  }
  return out;
}

Status UploadCorrection(Transport& transport, const BoardCorrection& table) {
  INSITU_ASSIGN_OR_RETURN(const auto commands, CorrectionUpload(table));
  uint8_t reply[kReplyBytes];
  for (size_t i = 0; i < commands.size(); ++i) {
    INSITU_RETURN_IF_ERROR(transport.Write(commands[i].data(), commands[i].size()));
    // WriteCorTable is answered; the board sends no reply to a WriteCorLine.
    if (i == 0) INSITU_RETURN_IF_ERROR(transport.Read(reply, sizeof reply));
  }
  return Status::Ok();
}

}  // namespace insitu::hw::lmc

namespace insitu::hw::lmc {

Result<std::array<uint16_t, 4>> Query(Transport& transport, uint16_t op, uint16_t p1, uint16_t p2,
                                      uint16_t p3, uint16_t p4) {
  return Query(transport, SingleCommand(op, p1, p2, p3, p4));
}

Result<std::array<uint16_t, 4>> Query(Transport& transport, const std::vector<uint8_t>& bytes) {
  INSITU_RETURN_IF_ERROR(transport.Write(bytes.data(), bytes.size()));
  uint8_t reply[kReplyBytes];
  INSITU_RETURN_IF_ERROR(transport.Read(reply, sizeof reply));
  std::array<uint16_t, 4> words{};
  for (size_t i = 0; i < words.size(); ++i) {
    words[i] = static_cast<uint16_t>(reply[2 * i] | (reply[2 * i + 1] << 8));
  }
  return words;
}

std::string BoardIdentity::Describe() const {
  char v[32];
  std::snprintf(v, sizeof v, "%04x %04x %04x", version[0], version[1], version[2]);
  return "serial " + serial + ", version " + v;
}

bool Answered(const std::vector<uint8_t>& command) {
  return command.size() == kCommandBytes && DecodeCommand(command.data())[0] != kWriteCorLine;
}

Result<std::vector<std::vector<uint8_t>>> StartupCommands(const BoardOptions& o,
                                                          const BoardCorrection& table) {
  const StartupOptions& s = o.startup;
  std::vector<std::vector<uint8_t>> out{SingleCommand(kReset)};
  if (table.offsets.empty()) {
    out.push_back(SingleCommand(kWriteCorTable, 0));
  } else {
    INSITU_ASSIGN_OR_RETURN(auto upload, CorrectionUpload(table));
    for (auto& c : upload) out.push_back(std::move(c));
  }
  const std::vector<std::array<uint16_t, 5>> rest = {
      {kEnableLaser, 0, 0, 0, 0},
      {kSetControlMode, s.control_mode, 0, 0, 0},
      {kSetLaserMode, s.laser_mode, 0, 0, 0},
      {kSetDelayMode, s.delay_mode, 0, 0, 0},
      {kSetTiming, s.timing_mode, 0, 0, 0},
      {kSetStandby, s.standby_1, s.standby_2, 0, 0},
      {kSetFirstPulseKiller, s.first_pulse_killer, 0, 0, 0},
      {kSetPwmHalfPeriod, s.pwm_half_period, 0, 0, 0},
      {kSetPwmPulseWidth, s.pwm_pulse_width, 0, 0, 0},
      {kFiberSetMo, 0, 0, 0, 0},
      {kSetFpkParam2, s.fpk2[0], s.fpk2[1], s.fpk2[2], s.fpk2[3]},
      {kSetFlyRes, s.fly_res[0], s.fly_res[1], s.fly_res[2], s.fly_res[3]},
      {kEnableZ, 0, 0, 0, 0},
      {kWriteAnalogPort1, s.analog_port_1, 0, 0, 0},
      {kEnableZ, 0, 0, 0, 0},
      {kDisableLaser, 0, 0, 0, 0},
  };
  for (const auto& c : rest) out.push_back(SingleCommand(c[0], c[1], c[2], c[3], c[4]));
  return out;
}

Result<BoardIdentity> StartUp(Transport& transport, const BoardOptions& options,
                              const BoardCorrection& table) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  BoardIdentity id;
  const auto serial = Query(transport, kGetSerialNo);
  if (!serial.ok()) return serial.status().Prefixed("reading the board's serial number");
  char hex[24];
  std::snprintf(hex, sizeof hex, "0x%04x%04x%04x%04x", (*serial)[0], (*serial)[1], (*serial)[2],
                (*serial)[3]);
  id.serial = hex;
  const auto version = Query(transport, kGetVersion);
  if (!version.ok()) return version.status().Prefixed("reading the board's version");
  id.version = *version;
  INSITU_ASSIGN_OR_RETURN(const auto commands, StartupCommands(options, table));
  uint8_t reply[kReplyBytes];
  bool enabled = false;  // EnableLaser went out: a failure after it disables the output again
  for (const auto& c : commands) {
    Status sent = transport.Write(c.data(), c.size());
    if (sent.ok() && Answered(c)) sent = transport.Read(reply, sizeof reply);
    if (!sent.ok()) {
      if (enabled) {
        for (uint16_t op : {kFiberSetMo, kDisableLaser}) {  // best effort
          const auto off = SingleCommand(op);
          if (transport.Write(off.data(), off.size()).ok())
            (void)transport.Read(reply, sizeof reply);
        }
      }
      return sent;
    }
    enabled = enabled || DecodeCommand(c.data())[0] == kEnableLaser;
  }
  // The analog outputs (the laser's power reference, the focus Z) settle.
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  return id;
}

}  // namespace insitu::hw::lmc
