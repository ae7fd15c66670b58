// The daemon's machine state (ros2_control's lifecycle: connected is not armed). The marking
// laser may be on only while Running; the eye-safe pointer is separate and needs no arming.
//
//   Idle --arm--> Armed --start--> Running --finish--> Done | Faulted | Cancelled
//   Armed --disarm--> Idle;  Done | Faulted | Cancelled --arm--> Armed, --disarm--> Idle
//   Done --start next--> Running (a queued job after one that ended done, armed for the queue)
//
// Every change is reported to the listeners (the daemon turns them into events for subscribed
// clients). Thread-safe: the job thread finishes, socket threads arm and disarm.
#pragma once

#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::daemon {

enum class MachineState { kIdle, kArmed, kRunning, kDone, kFaulted, kCancelled };

// "idle", "armed", "running", "done", "faulted", "cancelled".
const char* StateName(MachineState state);

enum class JobOutcome { kDone, kFaulted, kCancelled };

class StateMachine {
 public:
  // (from, to, reason): reason is the fault or cancel message, empty otherwise.
  using Listener = std::function<void(MachineState, MachineState, const std::string&)>;

  MachineState state() const;
  // True only while Running: the one state in which the marking laser may fire.
  bool laser_allowed() const;
  // The reason of the last Faulted or Cancelled, empty otherwise.
  std::string last_reason() const;

  // Errors: failed_precondition naming the current state (arm while Running, start while not
  // Armed, finish while not Running, disarm while Running).
  Status Arm();
  Status Disarm();
  Status Start();
  // The next queued job, straight from Done. Errors: failed_precondition in any other state
  // (the last job did not end done, or the operator disarmed meanwhile).
  Status StartNext();
  Status Finish(JobOutcome outcome, const std::string& reason = "");

  void AddListener(Listener listener);

 private:
  // Checks and moves under the lock; `next` gives the target state or why not.
  Status Move(const std::function<Result<MachineState>(MachineState)>& next,
              const std::string& reason);

  mutable std::mutex mutex_;
  MachineState state_ = MachineState::kIdle;
  std::string reason_;
  std::vector<Listener> listeners_;
};

}  // namespace insitu::daemon
