// The GRBL stage: a serial port (termios raw 8N1, non-blocking, every wait a poll() with a
// deadline) and the GRBL 1.1 conversation on it (protocol.h for the lines).
//
// Why it is done this way:
// - Moves go out in machine coordinates (G53), and in mm (G21) whatever the controller's modal
//   state, so work offsets set on a pendant (G54, G92) or inch mode never shift the cell's z.
// - "In position" is the "ok" of a "G4 P0" sent after the move: GRBL answers a dwell only once
//   the planner has run dry, whereas the move's own "ok" comes when it is planned, and polling
//   '?' for Idle right after it races the start of the motion. '?' is still polled meanwhile so
//   a feed hold or an open door fails the move at once instead of at the deadline; the position
//   is then checked against the target (a controller in check mode ($C) moves nothing).
// - After an ALARM the controller is reset (0x18) when it asks for it ("[MSG:Reset to
//   continue]", after hard and soft limits): until then GRBL answers nothing, not even '?', and
//   every later call would time out instead of naming the alarm. The reset moves nothing (the
//   motion has stopped already) and leaves the controller in Alarm, which the next call reports.
// - A lost port (hang-up, end of file, EIO) is latched and the descriptor closed, so every later
//   call returns the same status at once and the device node is free for a reopen.
#include <fcntl.h>
#include <poll.h>
#include <sys/file.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "hw/grbl/common.h"
#include "hw/grbl/protocol.h"
#include "hw/grbl/stage.h"
#include "insitu/core/log.h"

namespace insitu::hw::grbl {
namespace {

using Clock = std::chrono::steady_clock;
using Deadline = Clock::time_point;

Deadline After(double s) {
  return Clock::now() +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// poll()'s timeout until `deadline`, rounded up so a wait never ends just before it.
int MsUntil(Deadline deadline) {
  const auto ms = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return static_cast<int>(std::clamp<long long>(ms, 0, 60'000));
}

std::string ErrnoText(const char* what) { return std::string(what) + ": " + std::strerror(errno); }

// The serial line. Errors are the reason only (the caller names the controller), except a lost
// port, whose status is complete and latched.
class SerialPort {
 public:
  static Result<std::unique_ptr<SerialPort>> Open(const std::string& path, int baud) {
    const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
      if (errno == ENOENT) {
        return NotFound("no serial port " + path +
                        " (is the controller plugged in and powered? see /dev/serial/by-id)");
      }
      const std::string hint = errno == EACCES  ? " (add the user to the dialout group)"
                               : errno == EBUSY ? " (another program holds it)"
                                                : "";
      return DeviceError("cannot open the serial port " + path + ": " + std::strerror(errno) +
                         hint);
    }
    const auto fail = [&](const std::string& message) {
      ::close(fd);
      return DeviceError(message);
    };
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      return fail("the serial port " + path + " is held by another program (flock)");
    }
    termios t{};
    if (::tcgetattr(fd, &t) != 0) {
      return fail(path + " is not a serial port: " + ErrnoText("tcgetattr"));
    }
    ::cfmakeraw(&t);
    t.c_cflag &= ~(CSTOPB | PARENB | CRTSCTS | CSIZE);
    t.c_cflag |= CS8 | CLOCAL | CREAD;
    // Closing the port keeps DTR up: an Arduino GRBL resets (and forgets an unhomed position)
    // when DTR drops.
    t.c_cflag &= ~HUPCL;
    t.c_iflag &= ~(IXON | IXOFF | IXANY);
    // MIN 1: a read with nothing to read says EAGAIN, so 0 means the line hung up (with MIN 0
    // and TIME 0 Linux returns 0 for "nothing yet" too).
    t.c_cc[VMIN] = 1;
    t.c_cc[VTIME] = 0;
    const speed_t speed = *BaudConstant(baud);
    if (::cfsetispeed(&t, speed) != 0 || ::cfsetospeed(&t, speed) != 0 ||
        ::tcsetattr(fd, TCSANOW, &t) != 0) {
      return fail("cannot set " + path + " to " + std::to_string(baud) +
                  " baud 8N1 raw: " + std::strerror(errno));
    }
    ::tcflush(fd, TCIOFLUSH);  // bytes from before we opened answer nothing of ours
    return std::unique_ptr<SerialPort>(new SerialPort(fd, path));
  }

  ~SerialPort() {
    if (fd_ >= 0) ::close(fd_);
  }
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  const std::string& path() const { return path_; }
  // Ok, or why the port was lost (then every call returns it).
  const Status& lost() const { return lost_; }

  Status Write(std::string_view bytes, Deadline deadline) {
    size_t done = 0;
    while (done < bytes.size()) {
      if (!lost_.ok()) return lost_;
      const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
      if (n > 0) {
        done += static_cast<size_t>(n);
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && errno != EAGAIN) return Lose(ErrnoText("write"));
      pollfd p{fd_, POLLOUT, 0};
      const int r = ::poll(&p, 1, MsUntil(deadline));
      if (r < 0 && errno != EINTR) return Lose(ErrnoText("poll"));
      if (r > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
        return Lose("the device hung up");
      }
      if (r == 0 && Clock::now() >= deadline) {
        return DeviceError("writing to the port did not finish by the deadline (" +
                           std::to_string(bytes.size() - done) + " bytes left)");
      }
    }
    return Status::Ok();
  }

  // The next non-empty line without its "\r\n"; nullopt when `deadline` passes first (a
  // deadline in the past returns only what has arrived).
  Result<std::optional<std::string>> ReadLine(Deadline deadline) {
    for (;;) {
      for (size_t end = pending_.find_first_of("\r\n"); end != std::string::npos;
           end = pending_.find_first_of("\r\n")) {
        std::string line = pending_.substr(0, end);
        pending_.erase(0, end + 1);
        if (!line.empty()) return std::optional<std::string>(std::move(line));
      }
      if (!lost_.ok()) return lost_;
      if (pending_.size() > 4096) {
        // Noise without line ends: a wrong baud rate looks like this.
        Logger("hw")->warn("{}: dropping {} bytes without a line end (wrong baud rate?)", path_,
                           pending_.size());
        pending_.clear();
      }
      pollfd p{fd_, POLLIN, 0};
      const int n = ::poll(&p, 1, MsUntil(deadline));
      if (n < 0) {
        if (errno == EINTR) continue;
        return Lose(ErrnoText("poll"));
      }
      if (n == 0) {
        if (Clock::now() >= deadline) return std::optional<std::string>();
        continue;
      }
      if (p.revents & POLLNVAL) return Lose("the descriptor was closed");
      char buffer[512];
      const ssize_t got = ::read(fd_, buffer, sizeof buffer);
      if (got > 0) {
        pending_.append(buffer, static_cast<size_t>(got));
      } else if (got == 0) {
        return Lose("the device hung up (end of file)");
      } else if (errno == EAGAIN || errno == EINTR) {
        if (p.revents & (POLLHUP | POLLERR)) return Lose("the device hung up");
      } else {
        return Lose(ErrnoText("read"));
      }
    }
  }

 private:
  SerialPort(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}

  Status Lose(const std::string& reason) {
    lost_ = DeviceError("lost the serial port " + path_ + ": " + reason);
    Logger("hw")->error("{}", lost_.message());
    ::close(fd_);
    fd_ = -1;
    return lost_;
  }

  int fd_;
  std::string path_;
  std::string pending_;
  Status lost_;
};

// The conversation with the controller: commands and their replies, status queries, what to do
// with alarms and unsolicited lines. Errors are the reason only, without the controller's
// name; a lost port is the port's latched status.
class Controller {
 public:
  Controller(std::unique_ptr<SerialPort> port, const StageOptions& options)
      : port_(std::move(port)),
        options_(options),
        axis_(kAxes.find(options.axis)),
        name_("GRBL on " + port_->path()) {}

  const std::string& name() const { return name_; }
  const Status& lost() const { return port_->lost(); }
  const std::string& last_alarm() const { return last_alarm_; }
  void set_inch_reports(bool inch) { report_unit_mm_ = inch ? 25.4 : 1.0; }

  // The banner line, or "" when none came by `deadline`.
  Result<std::string> AwaitBanner(Deadline deadline) {
    for (;;) {
      INSITU_ASSIGN_OR_RETURN(std::optional<std::string> line, port_->ReadLine(deadline));
      if (!line) return std::string();
      if (Classify(*line).kind == LineKind::kBanner) return *line;
      Logger("hw")->debug("{} > {} (before the banner)", name_, *line);
    }
  }

  Status SoftReset() { return port_->Write("\x18", After(options_.timeout_s)); }

  // Sends `line` and waits for its "ok" until `deadline`; with `poll`, '?' every status_poll_s
  // meanwhile, and a state that cannot finish the motion (Alarm, Hold, Door, Sleep) fails it.
  // `settings` collects the "$N=v" lines of the reply.
  Status Command(const std::string& line, Deadline deadline, bool poll,
                 std::vector<std::string>* settings = nullptr) {
    INSITU_RETURN_IF_ERROR(Drain());
    Logger("hw")->debug("{} < {}", name_, line);
    const Deadline start = Clock::now();
    INSITU_RETURN_IF_ERROR(port_->Write(line + "\n", deadline));
    Deadline next_poll = poll ? After(options_.status_poll_s) : deadline;
    for (;;) {
      INSITU_ASSIGN_OR_RETURN(std::optional<std::string> reply,
                              port_->ReadLine(std::min(deadline, next_poll)));
      if (!reply) {
        if (Clock::now() >= deadline) {
          return DeviceError("no reply to '" + line + "' within " +
                             Fixed(std::chrono::duration<double>(deadline - start).count(), 1) +
                             " s");
        }
        INSITU_RETURN_IF_ERROR(port_->Write("?", deadline));
        next_poll = After(options_.status_poll_s);
        continue;
      }
      const Line kind = Classify(*reply);
      switch (kind.kind) {
        case LineKind::kOk:
          return Status::Ok();
        case LineKind::kError:
          return DeviceError(DescribeError(kind.code));
        case LineKind::kAlarm:
          return OnAlarm(kind.code);
        case LineKind::kBanner:
          return DeviceError("the controller restarted ('" + *reply +
                             "'); its position may be lost");
        case LineKind::kStatus: {
          INSITU_ASSIGN_OR_RETURN(StatusReport report, OnReport(*reply));
          if (poll) INSITU_RETURN_IF_ERROR(CanFinish(report));
          break;
        }
        case LineKind::kSetting:
          if (settings != nullptr) settings->push_back(*reply);
          break;
        default:
          Logger("hw")->debug("{} > {}", name_, *reply);
          break;
      }
    }
  }

  // One '?' and its report; the machine position of the stage's axis in mm, nullopt when the
  // report gives WPos and no work offset (WCO) has been seen yet.
  Result<std::pair<StatusReport, std::optional<double>>> Query(Deadline deadline) {
    INSITU_RETURN_IF_ERROR(Drain());  // a late report is not the answer to this '?'
    const Deadline start = Clock::now();
    INSITU_RETURN_IF_ERROR(port_->Write("?", deadline));
    for (;;) {
      INSITU_ASSIGN_OR_RETURN(std::optional<std::string> reply, port_->ReadLine(deadline));
      if (!reply) {
        return DeviceError("no reply to the status query '?' within " +
                           Fixed(std::chrono::duration<double>(deadline - start).count(), 1) +
                           " s");
      }
      const Line kind = Classify(*reply);
      if (kind.kind == LineKind::kAlarm) return OnAlarm(kind.code);
      if (kind.kind != LineKind::kStatus) {
        Unsolicited(*reply, kind);
        continue;
      }
      INSITU_ASSIGN_OR_RETURN(StatusReport report, OnReport(*reply));
      const std::vector<double>& axes = report.mpos.empty() ? report.wpos : report.mpos;
      if (axis_ >= axes.size()) {
        return DeviceError("its status report '" + *reply + "' has no " +
                           std::string(1, options_.axis) + " axis");
      }
      std::optional<double> machine_mm;
      if (!report.mpos.empty()) {
        machine_mm = report.mpos[axis_] * report_unit_mm_;
      } else if (axis_ < wco_.size()) {
        machine_mm = (report.wpos[axis_] + wco_[axis_]) * report_unit_mm_;
      }
      return std::make_pair(std::move(report), machine_mm);
    }
  }

  // Queries until the machine position is known: GRBL reporting WPos sends the work offset only
  // every 10 to 30 reports.
  Result<std::pair<StatusReport, double>> QueryPosition(Deadline deadline) {
    for (int i = 0; i < 40; ++i) {
      INSITU_ASSIGN_OR_RETURN(auto answer, Query(deadline));
      if (answer.second) return std::make_pair(std::move(answer.first), *answer.second);
    }
    return DeviceError("its status reports give WPos but no work offset (WCO) in 40 queries");
  }

 private:
  // Reads the lines that have arrived: late replies of a call that timed out, reports of the
  // last polls, an alarm raised since the last call.
  Status Drain() {
    for (;;) {
      INSITU_ASSIGN_OR_RETURN(std::optional<std::string> line, port_->ReadLine(Clock::now()));
      if (!line) return Status::Ok();
      const Line kind = Classify(*line);
      if (kind.kind == LineKind::kAlarm) return OnAlarm(kind.code);
      if (kind.kind == LineKind::kStatus) {
        INSITU_RETURN_IF_ERROR(OnReport(*line).status());
      } else {
        Unsolicited(*line, kind);
      }
    }
  }

  void Unsolicited(const std::string& line, Line kind) {
    switch (kind.kind) {
      case LineKind::kOk:
      case LineKind::kError:
        Logger("hw")->warn("{}: a late reply '{}' (to a command that timed out)", name_, line);
        break;
      case LineKind::kBanner:
        Logger("hw")->warn("{}: the controller restarted ('{}')", name_, line);
        break;
      default:
        Logger("hw")->debug("{} > {}", name_, line);
        break;
    }
  }

  Result<StatusReport> OnReport(const std::string& line) {
    Result<StatusReport> report = ParseStatusReport(line);
    if (!report.ok()) return DeviceError(report.status().message());
    if (!report->wco.empty()) wco_ = report->wco;
    return report;
  }

  Status CanFinish(const StatusReport& r) const {
    if (r.state == "Alarm") {
      return DeviceError("the controller went into ALARM" +
                         (last_alarm_.empty() ? std::string() : " (" + last_alarm_ + ")"));
    }
    if (r.state == "Hold" || r.state == "Door" || r.state == "Sleep") {
      return DeviceError("the controller is in " + DescribeState(r) + "; the move did not finish");
    }
    return Status::Ok();
  }

  // Remembers the alarm, lets the controller out of its wait for a reset (see the top), and
  // returns the alarm as the error.
  Status OnAlarm(int code) {
    last_alarm_ = DescribeAlarm(code);
    Logger("hw")->error("{}: {}", name_, last_alarm_);
    const Deadline deadline = After(options_.timeout_s);
    for (;;) {
      Result<std::optional<std::string>> line = port_->ReadLine(deadline);
      if (!line.ok()) return line.status();
      if (!*line) break;
      const Line kind = Classify(**line);
      if (kind.kind == LineKind::kBanner) break;
      if (kind.kind == LineKind::kMessage &&
          (*line)->find("Reset to continue") != std::string::npos) {
        Logger("hw")->info("{}: soft reset to leave the alarm's wait", name_);
        INSITU_RETURN_IF_ERROR(SoftReset());
      }
    }
    return DeviceError(last_alarm_);
  }

  std::unique_ptr<SerialPort> port_;
  StageOptions options_;
  size_t axis_;
  std::string name_;
  double report_unit_mm_ = 1.0;
  std::vector<double> wco_;  // the last work coordinate offset reported, report units
  std::string last_alarm_;
};

class GrblStage : public Stage {
 public:
  explicit GrblStage(const StageOptions& options) : options_(options) {}

  // The opening sequence (OpenStage's contract in grbl.h).
  Status Open(std::unique_ptr<SerialPort> port) {
    controller_ = std::make_unique<Controller>(std::move(port), options_);
    Controller& c = *controller_;
    INSITU_ASSIGN_OR_RETURN(std::string banner, c.AwaitBanner(After(options_.banner_wait_s)));
    if (banner.empty()) {
      Logger("hw")->info("{}: no banner within {} s, soft reset", c.name(),
                         Fixed(options_.banner_wait_s, 2));
      INSITU_RETURN_IF_ERROR(Fail(c.SoftReset(), "soft reset"));
      INSITU_ASSIGN_OR_RETURN(banner, c.AwaitBanner(After(options_.timeout_s)));
    }
    if (banner.empty()) {
      return DeviceError(c.name() + ": no reply: no GRBL banner within " +
                         Fixed(options_.banner_wait_s, 1) + " s of opening the port nor " +
                         Fixed(options_.timeout_s, 1) +
                         " s after a soft reset (0x18); is a GRBL controller on this port, at " +
                         std::to_string(options_.baud) + " baud, and powered?");
    }
    if (!IsVersion11(banner)) {
      return DeviceError(c.name() + " says '" + banner + "': this backend speaks GRBL 1.1");
    }

    std::vector<std::string> lines;
    INSITU_RETURN_IF_ERROR(Fail(c.Command("$$", After(options_.timeout_s), false, &lines),
                                "reading its settings ($$)"));
    std::map<int, double> settings;
    for (const std::string& l : lines) {
      if (const auto s = ParseSetting(l)) settings[s->first] = s->second;
    }
    const auto flag = [&](int n) {
      return settings.count(n) != 0 && (static_cast<int>(settings[n]) & 1) != 0;
    };
    const bool homing = flag(22);
    c.set_inch_reports(flag(13));

    INSITU_ASSIGN_OR_RETURN(auto state, Fail(c.Query(After(options_.timeout_s)), "status query"));
    if (state.first.state == "Alarm" && !options_.home_on_open) {
      return FailedPrecondition(
          c.name() + " is in ALARM" +
          (homing ? " (homing is enabled, $22=1: GRBL starts locked until it homes)"
                  : std::string()) +
          "; set home_on_open to home it ($H) when the stage opens, or home it first");
    }
    if (options_.home_on_open) {
      if (!homing) {
        return FailedPrecondition(
            c.name() +
            ": home_on_open is set but homing is disabled on the controller ($22=0): enable "
            "homing, or set home_on_open false for a stage without limit switches");
      }
      Logger("hw")->info("{}: homing ($H)", c.name());
      INSITU_RETURN_IF_ERROR(
          Fail(c.Command("$H", After(options_.homing_timeout_s), false), "homing ($H) failed"));
    }
    INSITU_ASSIGN_OR_RETURN(auto ready,
                            Fail(c.QueryPosition(After(options_.timeout_s)), "status query"));
    if (ready.first.state != "Idle") {
      return DeviceError(c.name() + " is " + DescribeState(ready.first) +
                         " after opening, not Idle");
    }
    Logger("hw")->info("{} ({}): ready at z = {} mm (machine {}{})", c.name(), banner,
                       Fixed(CellFromMachine(ready.second), 3), options_.axis,
                       Fixed(ready.second, 3));
    return Status::Ok();
  }

  double min_z_mm() const override { return options_.min_z_mm; }
  double max_z_mm() const override { return options_.max_z_mm; }

  Result<double> Position() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    Controller& c = *controller_;
    if (!c.lost().ok()) return c.lost();
    const std::string what = "position query";
    INSITU_ASSIGN_OR_RETURN(auto now, Fail(c.QueryPosition(After(options_.timeout_s)), what));
    if (now.first.state == "Alarm") {
      return DeviceError(c.name() + ": " + what + ": " + InAlarm() +
                         "; its position is not trustworthy until it homes (reopen the stage)");
    }
    return CellFromMachine(now.second);
  }

  Status MoveTo(double z_mm) override {
    std::lock_guard<std::mutex> lock(mutex_);
    Controller& c = *controller_;
    if (!c.lost().ok()) return c.lost();
    if (!(z_mm >= options_.min_z_mm && z_mm <= options_.max_z_mm)) {
      return OutOfRange("z = " + Fixed(z_mm, 3) + " mm is outside the stage's travel [" +
                        Fixed(options_.min_z_mm, 3) + ", " + Fixed(options_.max_z_mm, 3) +
                        "] mm (" + c.name() + ")");
    }
    const double target = MachineFromCell(z_mm);
    const std::string axis_target = options_.axis + Fixed(target, 4);
    const std::string what = "move to z = " + Fixed(z_mm, 3) + " mm (machine " + axis_target + ")";

    INSITU_ASSIGN_OR_RETURN(auto from, Fail(c.QueryPosition(After(options_.timeout_s)), what));
    INSITU_RETURN_IF_ERROR(RequireIdle(from.first, what));
    INSITU_RETURN_IF_ERROR(
        Fail(c.Command("G21 G90 G53 G1 " + axis_target + " F" + Fixed(options_.feed_mm_per_min, 1),
                       After(options_.timeout_s), false),
             what));
    const double motion_s = std::abs(target - from.second) / options_.feed_mm_per_min * 60.0;
    const Deadline deadline = After(options_.timeout_s + 1.5 * motion_s);
    INSITU_RETURN_IF_ERROR(Fail(c.Command("G4 P0", deadline, true), what));

    // A report still saying Run was asked for before the motion ended: ask again.
    INSITU_ASSIGN_OR_RETURN(auto at, Fail(c.QueryPosition(After(options_.timeout_s)), what));
    while ((at.first.state == "Run" || at.first.state == "Jog") && Clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::duration<double>(options_.status_poll_s));
      INSITU_ASSIGN_OR_RETURN(at, Fail(c.QueryPosition(After(options_.timeout_s)), what));
    }
    INSITU_RETURN_IF_ERROR(RequireIdle(at.first, what));
    if (!(std::abs(at.second - target) <= options_.position_tolerance_mm)) {
      return DeviceError(c.name() + ": " + what + ": it stopped at machine " + options_.axis +
                         Fixed(at.second, 4) + ", " + Fixed(std::abs(at.second - target), 4) +
                         " mm from the target (tolerance " +
                         Fixed(options_.position_tolerance_mm, 4) + " mm)");
    }
    return Status::Ok();
  }

 private:
  double MachineFromCell(double z_mm) const {
    return options_.machine_zero_mm + options_.direction * z_mm;
  }
  double CellFromMachine(double machine_mm) const {
    return (machine_mm - options_.machine_zero_mm) * options_.direction;  // direction is +-1
  }

  // "GRBL on <port>: <what>: <reason>"; a lost port's status as it is.
  Status Fail(const Status& s, const std::string& what) const {
    if (s.ok()) return s;
    if (!controller_->lost().ok()) return controller_->lost();
    return Status(s.code(), controller_->name() + ": " + what + ": " + s.message());
  }
  template <typename T>
  Result<T> Fail(Result<T> r, const std::string& what) const {
    if (r.ok()) return r;
    return Fail(r.status(), what);
  }

  std::string InAlarm() const {
    const std::string& alarm = controller_->last_alarm();
    return "the controller is in ALARM" + (alarm.empty() ? std::string() : " since " + alarm);
  }

  Status RequireIdle(const StatusReport& r, const std::string& what) const {
    if (r.state == "Idle") return Status::Ok();
    if (r.state == "Alarm") {
      return DeviceError(controller_->name() + ": " + what + ": " + InAlarm() +
                         "; reopen the stage to home it");
    }
    return DeviceError(controller_->name() + ": " + what + ": the controller is " +
                       DescribeState(r) + ", not Idle");
  }

  StageOptions options_;
  mutable std::mutex mutex_;  // one conversation at a time
  std::unique_ptr<Controller> controller_;
};

}  // namespace


Result<std::unique_ptr<Stage>> OpenStage(const StageOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  INSITU_ASSIGN_OR_RETURN(std::unique_ptr<SerialPort> port,
                          SerialPort::Open(options.port, options.baud));
  auto stage = std::make_unique<GrblStage>(options);
  INSITU_RETURN_IF_ERROR(stage->Open(std::move(port)));
  return std::unique_ptr<Stage>(std::move(stage));
}

}  // namespace insitu::hw::grbl
