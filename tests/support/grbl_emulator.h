// A GRBL 1.1 controller with one Z axis on a pseudo-terminal, for the grbl stage's tests: the
// test opens port() as the serial device. It speaks what the stage uses, the way GRBL does:
// - starts silent (no DTR reset on a pty) and in Alarm when homing is enabled; 0x18 (soft
//   reset) prints the banner, and "[MSG:'$H'|'$X' to unlock]" in Alarm;
// - "$$" (settings), "$H" (homing: machine Z = -pulloff, or ALARM:N and a reset of its own when
//   told to fail), "$X" (unlock), "$J=" jogs (error:15 beyond the travel);
// - G0/G1/G4/G21/G53/G90 lines: a motion is answered "ok" when it starts and takes
//   |dz| / rate * time_scale real time (status Run, then Idle); lines after it wait until it is
//   done, so "G4 P0" is answered once it has ended; in Alarm G-code gets error:9;
// - soft limits ($20): a target outside [-max travel, 0] raises ALARM:2, and after it (and after
//   a hard limit, ALARM:1) it waits for a reset answering nothing, not even '?';
// - '?' is answered at once: "<Idle|MPos:0.000,0.000,-1.000|FS:0,0>" (or WPos, with WCO on every
//   tenth report counting from the third), '!' holds a motion (Hold:0), '~' resumes it.
// Faults are injected from the test thread; every method is thread-safe.
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace insitu::testing {

struct GrblEmulatorOptions {
  bool homing_enabled = true;           // $22
  bool soft_limits = true;              // $20: the machine travel is [-max_travel_mm, 0]
  double max_travel_mm = 50.0;          // $132
  double pulloff_mm = 1.0;              // $27: machine Z after homing is -pulloff_mm
  double max_rate_mm_per_min = 1000.0;  // $112: the G0 rate
  double time_scale = 0.1;              // real seconds per emulated second of motion
  double homing_s = 0.02;               // real seconds a homing cycle takes
  bool report_wpos = false;             // $10=0: reports give WPos (and WCO now and then), not MPos
  double wco_z_mm = 0.0;                // the work offset (G54) of Z
};

class GrblEmulator {
 public:
  explicit GrblEmulator(GrblEmulatorOptions options = {});
  ~GrblEmulator();
  GrblEmulator(const GrblEmulator&) = delete;
  GrblEmulator& operator=(const GrblEmulator&) = delete;

  // The slave side's path, e.g. /dev/pts/7.
  const std::string& port() const { return port_; }

  // A limit switch at machine z: a motion reaching it stops there with ALARM:1.
  void SetLimitSwitchAt(double machine_z_mm);
  // The next G-code line is refused with error:N.
  void RefuseNextLine(int error_code);
  // The next homing cycle fails with ALARM:N.
  void FailHoming(int alarm_code);
  // Reads and drops everything, answering nothing.
  void SetMute(bool mute);
  // A feed hold ('!' on the pendant).
  void FeedHold();
  // Closes the master side, as when the cable is pulled; returns once it is closed.
  void Unplug();

  double machine_z_mm() const;
  std::string state() const;
  // Every line received, in order (real-time bytes are not lines).
  std::vector<std::string> lines() const;

 private:
  using Clock = std::chrono::steady_clock;
  struct Motion {
    double from_mm, to_mm;
    Clock::time_point start;
    double duration_s;
  };

  void Run();
  void OnByte(char c);
  void ProcessQueue();
  bool Busy() const;
  void Execute(const std::string& line);
  void GCode(const std::string& line, bool jog);
  void StartMotion(double to_mm, double rate_mm_per_min, const char* state);
  void Tick();
  void Report();
  void Reset();
  void Alarm(int code, bool wait_for_reset);
  void Send(const std::string& line);

  GrblEmulatorOptions options_;
  std::string port_;
  int master_ = -1;
  int slave_ = -1;  // held open so the line does not hang up between the stage's opens

  mutable std::mutex mutex_;
  std::condition_variable unplugged_cv_;
  bool stop_ = false;
  bool unplug_ = false;
  bool unplugged_ = false;

  std::string state_;
  int hold_ = -1;  // Hold substate, -1 when not held
  Clock::time_point held_at_;
  bool waiting_for_reset_ = false;
  double z_mm_ = 0.0;           // machine
  double feed_mm_per_min_ = 0;  // modal F, 0: not set
  std::optional<Motion> motion_;
  std::optional<Clock::time_point> homing_done_;
  std::optional<Clock::time_point> dwell_done_;
  std::deque<std::string> queue_;
  std::string line_;
  int reports_ = 0;

  bool mute_ = false;
  int refuse_next_ = 0;
  int homing_alarm_ = 0;
  std::optional<double> limit_switch_mm_;
  std::vector<std::string> lines_;

  std::thread thread_;
};

}  // namespace insitu::testing
