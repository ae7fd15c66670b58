// The GRBL emulator's thread: reads the master side every 2 ms, answers real-time bytes at once,
// executes lines in order (a line waits while a motion, a dwell or a homing cycle runs) and
// advances the motion on the clock. Independent of src/hw/grbl on purpose: a misreading of the
// protocol shared by both would pass unnoticed.
#include "support/grbl_emulator.h"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace insitu::testing {
namespace {

constexpr char kBanner[] = "Grbl 1.1h ['$' for help]";

std::string Mm(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", v);
  return b;
}

}  // namespace

GrblEmulator::GrblEmulator(GrblEmulatorOptions options) : options_(options) {
  master_ = ::posix_openpt(O_RDWR | O_NOCTTY);
  if (master_ < 0 || ::grantpt(master_) != 0 || ::unlockpt(master_) != 0) {
    throw std::runtime_error("grbl emulator: cannot open a pseudo-terminal");
  }
  char name[128];
  if (::ptsname_r(master_, name, sizeof name) != 0) {
    throw std::runtime_error("grbl emulator: ptsname failed");
  }
  port_ = name;
  slave_ = ::open(name, O_RDWR | O_NOCTTY);
  if (slave_ < 0) throw std::runtime_error("grbl emulator: cannot open " + port_);
  // Raw from the start: no echo of what the stage sends, no "\n" -> "\r\n" on what we send.
  termios t{};
  ::tcgetattr(slave_, &t);
  ::cfmakeraw(&t);
  ::tcsetattr(slave_, TCSANOW, &t);
  ::fcntl(master_, F_SETFL, ::fcntl(master_, F_GETFL) | O_NONBLOCK);
  state_ = options_.homing_enabled ? "Alarm" : "Idle";
  thread_ = std::thread([this] { Run(); });
}

GrblEmulator::~GrblEmulator() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  thread_.join();
  if (master_ >= 0) ::close(master_);
  ::close(slave_);
}

void GrblEmulator::SetLimitSwitchAt(double machine_z_mm) {
  std::lock_guard<std::mutex> lock(mutex_);
  limit_switch_mm_ = machine_z_mm;
}

void GrblEmulator::RefuseNextLine(int error_code) {
  std::lock_guard<std::mutex> lock(mutex_);
  refuse_next_ = error_code;
}

void GrblEmulator::FailHoming(int alarm_code) {
  std::lock_guard<std::mutex> lock(mutex_);
  homing_alarm_ = alarm_code;
}

void GrblEmulator::SetMute(bool mute) {
  std::lock_guard<std::mutex> lock(mutex_);
  mute_ = mute;
}

void GrblEmulator::FeedHold() {
  std::lock_guard<std::mutex> lock(mutex_);
  OnByte('!');
}

void GrblEmulator::Unplug() {
  std::unique_lock<std::mutex> lock(mutex_);
  unplug_ = true;
  unplugged_cv_.wait_for(lock, std::chrono::seconds(2), [this] { return unplugged_; });
}

double GrblEmulator::machine_z_mm() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return z_mm_;
}

std::string GrblEmulator::state() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

std::vector<std::string> GrblEmulator::lines() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lines_;
}

void GrblEmulator::Run() {
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return;
      if (unplug_) {
        ::close(master_);
        master_ = -1;
        unplugged_ = true;
        unplugged_cv_.notify_all();
        return;
      }
    }
    pollfd p{master_, POLLIN, 0};
    char buffer[256];
    ssize_t got = 0;
    if (::poll(&p, 1, 2) > 0 && (p.revents & POLLIN)) got = ::read(master_, buffer, sizeof buffer);
    std::lock_guard<std::mutex> lock(mutex_);
    for (ssize_t i = 0; i < got; ++i) OnByte(buffer[i]);
    Tick();
  }
}

void GrblEmulator::OnByte(char c) {
  if (mute_) return;
  if (c == 0x18) {
    Reset();
    return;
  }
  // GRBL's wait after a hard or soft limit takes nothing but a reset.
  if (waiting_for_reset_) return;
  if (c == '?') {
    Report();
    return;
  }
  if (c == '!') {
    if (motion_ && hold_ < 0) {
      hold_ = 0;
      held_at_ = Clock::now();
      state_ = "Hold";
    }
    return;
  }
  if (c == '~') {
    if (motion_ && hold_ >= 0) {
      motion_->start += Clock::now() - held_at_;
      hold_ = -1;
      state_ = "Run";
    }
    return;
  }
  if (c == '\n' || c == '\r') {
    if (!line_.empty()) {
      lines_.push_back(line_);
      queue_.push_back(line_);
      line_.clear();
      ProcessQueue();
    }
    return;
  }
  line_ += c;
}

bool GrblEmulator::Busy() const {
  return motion_.has_value() || homing_done_.has_value() || dwell_done_.has_value();
}

void GrblEmulator::ProcessQueue() {
  while (!queue_.empty() && !Busy() && !waiting_for_reset_) {
    const std::string line = queue_.front();
    queue_.pop_front();
    Execute(line);
  }
}

void GrblEmulator::Execute(const std::string& line) {
  if (line == "$$") {
    const std::string settings[] = {
        "$10=" + std::string(options_.report_wpos ? "0" : "1"),
        "$13=0",
        "$20=" + std::string(options_.soft_limits ? "1" : "0"),
        "$22=" + std::string(options_.homing_enabled ? "1" : "0"),
        "$27=" + Mm(options_.pulloff_mm),
        "$112=" + Mm(options_.max_rate_mm_per_min),
        "$132=" + Mm(options_.max_travel_mm),
    };
    for (const auto& s : settings) Send(s);
    Send("ok");
  } else if (line == "$H") {
    if (!options_.homing_enabled) {
      Send("error:5");
      return;
    }
    state_ = "Home";
    homing_done_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(options_.homing_s));
  } else if (line == "$X") {
    if (state_ == "Alarm") {
      state_ = "Idle";
      Send("[MSG:Caution: Unlocked]");
    }
    Send("ok");
  } else if (line.rfind("$J=", 0) == 0) {
    GCode(line.substr(3), true);
  } else if (line[0] == '$') {
    Send("error:3");
  } else {
    GCode(line, false);
  }
}

void GrblEmulator::GCode(const std::string& line, bool jog) {
  if (refuse_next_ != 0) {
    Send("error:" + std::to_string(refuse_next_));
    refuse_next_ = 0;
    return;
  }
  if (state_ == "Alarm") {
    Send("error:9");
    return;
  }
  std::optional<double> z, feed, dwell;
  int motion = -1;
  bool machine = false;
  for (size_t i = 0; i < line.size();) {
    if (line[i] == ' ') {
      ++i;
      continue;
    }
    const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(line[i])));
    if (!std::isalpha(static_cast<unsigned char>(letter))) {
      Send("error:1");
      return;
    }
    const char* begin = line.c_str() + i + 1;
    char* end = nullptr;
    const double value = std::strtod(begin, &end);
    if (end == begin) {
      Send("error:2");
      return;
    }
    i = static_cast<size_t>(end - line.c_str());
    if (letter == 'G') {
      if (value == 0 || value == 1) {
        motion = static_cast<int>(value);
      } else if (value == 4) {
        dwell = 0.0;
      } else if (value == 53) {
        machine = true;
      } else if (value != 21 && value != 90) {
        Send("error:20");
        return;
      }
    } else if (letter == 'Z') {
      z = value;
    } else if (letter == 'F') {
      feed = value;
    } else if (letter == 'P') {
      dwell = value;
    } else if (letter != 'X' && letter != 'Y') {
      Send("error:20");
      return;
    }
  }
  if (feed) feed_mm_per_min_ = *feed;
  if (dwell) {
    dwell_done_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                     std::chrono::duration<double>(*dwell));
    return;  // "ok" when it ends
  }
  if (!z) {
    Send("ok");
    return;
  }
  if (jog && !feed) {
    Send("error:16");
    return;
  }
  const double target = machine ? *z : *z + options_.wco_z_mm;
  const bool beyond = target > 0.0 || target < -options_.max_travel_mm;
  if (options_.soft_limits && beyond) {
    if (jog) {
      Send("error:15");
    } else {
      Alarm(2, true);
    }
    return;
  }
  const double rate = !jog && motion == 0 ? options_.max_rate_mm_per_min : feed_mm_per_min_;
  if (rate <= 0) {
    Send("error:22");
    return;
  }
  StartMotion(target, rate, jog ? "Jog" : "Run");
  Send("ok");
}

void GrblEmulator::StartMotion(double to_mm, double rate_mm_per_min, const char* state) {
  motion_ = Motion{z_mm_, to_mm, Clock::now(),
                   std::abs(to_mm - z_mm_) / rate_mm_per_min * 60.0 * options_.time_scale};
  state_ = state;
}

void GrblEmulator::Tick() {
  if (master_ < 0 || waiting_for_reset_) return;
  const auto now = Clock::now();
  if (homing_done_ && now >= *homing_done_) {
    homing_done_.reset();
    if (homing_alarm_ != 0) {
      // A failed homing cycle: GRBL reports the alarm and resets itself.
      state_ = "Alarm";
      Send("ALARM:" + std::to_string(homing_alarm_));
      homing_alarm_ = 0;
      Send(kBanner);
      Send("[MSG:'$H'|'$X' to unlock]");
    } else {
      z_mm_ = -options_.pulloff_mm;
      state_ = "Idle";
      Send("ok");
    }
  }
  if (dwell_done_ && !motion_ && now >= *dwell_done_) {
    dwell_done_.reset();
    Send("ok");
  }
  if (motion_ && hold_ < 0) {
    const double f =
        motion_->duration_s <= 0
            ? 1.0
            : std::min(1.0, std::chrono::duration<double>(now - motion_->start).count() /
                                motion_->duration_s);
    const double z = motion_->from_mm + (motion_->to_mm - motion_->from_mm) * f;
    if (limit_switch_mm_ && (z - *limit_switch_mm_) * (z_mm_ - *limit_switch_mm_) <= 0 &&
        z != z_mm_) {
      z_mm_ = *limit_switch_mm_;
      Alarm(1, true);
      return;
    }
    z_mm_ = z;
    if (f >= 1.0) {
      motion_.reset();
      state_ = "Idle";
    }
  }
  ProcessQueue();
}

void GrblEmulator::Report() {
  const bool wco = reports_ % 10 == 3;
  ++reports_;
  std::string r = "<" + state_ + (hold_ >= 0 ? ":" + std::to_string(hold_) : std::string());
  const double z = options_.report_wpos ? z_mm_ - options_.wco_z_mm : z_mm_;
  r += std::string(options_.report_wpos ? "|WPos:" : "|MPos:") + "0.000,0.000," + Mm(z);
  r += "|Bf:15,128|FS:" + std::to_string(static_cast<int>(motion_ ? feed_mm_per_min_ : 0)) + ",0";
  if (wco) r += "|WCO:0.000,0.000," + Mm(options_.wco_z_mm);
  Send(r + ">");
}

void GrblEmulator::Reset() {
  line_.clear();
  queue_.clear();
  dwell_done_.reset();
  if (motion_ || homing_done_) {
    state_ = "Alarm";
    Send(homing_done_ ? "ALARM:6" : "ALARM:3");  // reset during homing, during a motion
    motion_.reset();
    homing_done_.reset();
  }
  hold_ = -1;
  waiting_for_reset_ = false;
  feed_mm_per_min_ = 0;
  Send(kBanner);
  if (state_ == "Alarm") Send("[MSG:'$H'|'$X' to unlock]");
}

void GrblEmulator::Alarm(int code, bool wait_for_reset) {
  state_ = "Alarm";
  motion_.reset();
  hold_ = -1;
  queue_.clear();
  Send("ALARM:" + std::to_string(code));
  if (wait_for_reset) {
    waiting_for_reset_ = true;
    Send("[MSG:Reset to continue]");
  }
}

void GrblEmulator::Send(const std::string& line) {
  if (master_ < 0) return;
  const std::string bytes = line + "\r\n";
  // Non-blocking: a stage that stopped reading loses replies instead of stalling the thread.
  [[maybe_unused]] const ssize_t n = ::write(master_, bytes.data(), bytes.size());
}

}  // namespace insitu::testing
