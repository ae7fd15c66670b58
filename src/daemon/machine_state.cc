#include "insitu/daemon/machine_state.h"

namespace insitu::daemon {

const char* StateName(MachineState s) {
  switch (s) {
    case MachineState::kIdle:
      return "idle";
    case MachineState::kArmed:
      return "armed";
    case MachineState::kRunning:
      return "running";
    case MachineState::kDone:
      return "done";
    case MachineState::kFaulted:
      return "faulted";
    case MachineState::kCancelled:
      return "cancelled";
  }
  return "unknown";
}

MachineState StateMachine::state() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

bool StateMachine::laser_allowed() const { return state() == MachineState::kRunning; }

std::string StateMachine::last_reason() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reason_;
}

// Each transition checks and moves under one lock (no other thread can slip in between), then
// tells the listeners outside it (a listener may read the state).
Status StateMachine::Arm() {
  return Move(
      [](MachineState s) -> Result<MachineState> {
        if (s == MachineState::kRunning) return FailedPrecondition("cannot arm: a job is running");
        return MachineState::kArmed;
      },
      "");
}

Status StateMachine::StartNext() {
  return Move(
      [](MachineState s) -> Result<MachineState> {
        if (s != MachineState::kDone) {
          return FailedPrecondition(std::string("a queued job starts only after a job ended done; "
                                                "the machine is ") +
                                    StateName(s));
        }
        return MachineState::kRunning;
      },
      "");
}

Status StateMachine::Disarm() {
  return Move(
      [](MachineState s) -> Result<MachineState> {
        if (s == MachineState::kRunning) {
          return FailedPrecondition("cannot disarm while a job is running: cancel it first");
        }
        return MachineState::kIdle;
      },
      "");
}

Status StateMachine::Start() {
  return Move(
      [](MachineState s) -> Result<MachineState> {
        if (s != MachineState::kArmed) {
          return FailedPrecondition(std::string("cannot start a job: the machine is ") +
                                    StateName(s) + ", not armed");
        }
        return MachineState::kRunning;
      },
      "");
}

Status StateMachine::Finish(JobOutcome outcome, const std::string& reason) {
  return Move(
      [outcome](MachineState s) -> Result<MachineState> {
        if (s != MachineState::kRunning) {
          return FailedPrecondition(std::string("no job to finish: the machine is ") +
                                    StateName(s));
        }
        return outcome == JobOutcome::kDone      ? MachineState::kDone
               : outcome == JobOutcome::kFaulted ? MachineState::kFaulted
                                                 : MachineState::kCancelled;
      },
      outcome == JobOutcome::kDone ? "" : reason);
}

void StateMachine::AddListener(Listener listener) {
  std::lock_guard<std::mutex> lock(mutex_);
  listeners_.push_back(std::move(listener));
}

Status StateMachine::Move(const std::function<Result<MachineState>(MachineState)>& next,
                          const std::string& reason) {
  MachineState from, to;
  std::vector<Listener> listeners;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    from = state_;
    Result<MachineState> target = next(from);
    if (!target.ok()) return target.status();
    to = *target;
    if (to == from) return Status::Ok();  // arming an armed machine: nothing happens
    state_ = to;
    reason_ = reason;
    listeners = listeners_;
  }
  for (const Listener& l : listeners) l(from, to, reason);
  return Status::Ok();
}

}  // namespace insitu::daemon
