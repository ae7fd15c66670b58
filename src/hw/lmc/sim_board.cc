#include "hw/lmc/sim_board.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <deque>
#include <mutex>
#include <set>
#include <thread>

namespace insitu::hw::lmc {

struct SimBoard::Impl {
  std::shared_ptr<sim::SimWorld> world;
  BoardOptions options;
  double units_per_ms_per_mm_s = 0.0;  // speed words: units per ms at 1 mm/s

  mutable std::mutex mutex;
  std::deque<std::array<uint8_t, kReplyBytes>> replies;
  std::vector<Command> buffer;  // received, not yet executing
  bool list_open = false;       // ExecuteList since the last ResetList: later packets run on
  std::thread runner;
  std::atomic<bool> running{false};  // a list executes (BUSY): until its end-of-list, or stopped
  bool starved = false;  // it ran out of commands before its end-of-list: busy, awaiting more
  std::atomic<bool> abort{false};
  SimBoardLog log;
  uint16_t ports_now = 0;  // the runner's port word during a triggered sweep
  // The list parameters the board holds (they persist from list to list, as on the board).
  sim::MarkingParams params;
  double z_mm = 0.0;
  // A triggered sweep as the runner executes it, packet by packet: where the mirrors are,
  // whether the trigger rose since the line's start, and the list time not yet run on the
  // world's clock (a line's sweep starts only once its far end is known).
  struct Sweep {
    bool active = false;
    bool pulse_pending = false;
    Eigen::Vector3d at = Eigen::Vector3d::Zero();
    double pending_s = 0.0;   // list time since the world's clock last moved
    double to_pulse_s = 0.0;  // of it, before the pulse
  } sweep;

  // The start-up commands received since power-up or the last Reset (StartupCommands).
  std::set<uint16_t> startup_seen;
  double sweep_jump_delay_s = 0.0;  // a triggered sweep's jump delay (the list parameter)

  void Reply(uint16_t status) { Reply({0, 0, 0, status}); }
  void Reply(const std::array<uint16_t, 4>& words) {
    std::array<uint8_t, kReplyBytes> r{};
    for (size_t i = 0; i < words.size(); ++i) {
      r[2 * i] = static_cast<uint8_t>(words[i] & 0xFF);
      r[2 * i + 1] = static_cast<uint8_t>(words[i] >> 8);
    }
    replies.push_back(r);
  }

  void Reject(const std::string& what) { log.rejected.push_back(what); }

  static std::string Hex(uint16_t op) {
    char s[8];
    std::snprintf(s, sizeof s, "0x%04x", op);
    return s;
  }

  // What a board needs before it runs a list: Reset, a correction table (loaded or blank) and
  // the modes EzCad sets (StartupCommands).
  bool Started() const {
    for (uint16_t op :
         {kReset, kWriteCorTable, kSetControlMode, kSetLaserMode, kSetDelayMode, kSetTiming,
          kSetStandby, kSetFirstPulseKiller, kSetPwmHalfPeriod, kSetPwmPulseWidth}) {
      if (!startup_seen.count(op)) return false;
    }
    return true;
  }

  void Join() {
    if (runner.joinable()) runner.join();
  }

  // Starts the runner on what is buffered (under mutex), or resumes a starved list with it.
  // The board runs a list until it executes an end-of-list; a list whose commands run out
  // before one keeps the board busy, waiting for the rest (as a real board does, or runs on
  // into stale list memory), until more packets come or StopExecute.
  void StartLocked() {
    if (buffer.empty() || (running && !starved)) return;
    if (runner.joinable()) runner.join();  // finished, or starved: the thread has returned
    if (!starved) ++log.lists_executed;
    starved = false;
    std::vector<Command> commands;
    commands.swap(buffer);
    running = true;
    abort = false;
    runner = std::thread([this, commands = std::move(commands)]() mutable {
      for (;;) {
        const bool ended = Execute(commands, /*locked=*/false);
        std::lock_guard<std::mutex> lock(mutex);
        if (abort) {
          running = false;
          return;
        }
        if (ended) {
          ++log.end_of_lists;
          running = false;
          return;
        }
        if (list_open && !buffer.empty()) {  // packets that streamed in meanwhile
          commands.clear();
          commands.swap(buffer);
          continue;
        }
        starved = true;  // still running: BUSY until the rest of the list comes
        ++log.starved;
        return;
      }
    });
  }

  // A list that marks nothing and turns the pointer port on (not a triggered sweep: that one
  // runs on the runner, on the head's clock).
  bool IsLightList(const std::vector<Command>& commands) const {
    bool pointer = false;
    for (const Command& c : commands) {
      if (c[0] == kMarkTo || Rises(c)) return false;
      if (c[0] == kWritePortList) pointer = (c[1] & options.pointer_port) != 0;
    }
    return pointer;
  }

  // A list port write that raises the camera's trigger output.
  bool Rises(const Command& c) const {
    return c[0] == kWritePortList && options.trigger_port != 0 && (c[1] & options.trigger_port);
  }

  // The runner's part of a triggered sweep. Each line: jump to its start and settle, the
  // trigger rises (the camera exposes from there), then passes back and forth: the world's
  // pointer sweeps the line between its start and the first pass's end, and the pulse comes
  // after the jump and the settle on the world's clock.
  // True once it has executed the list's end-of-list.
  bool ExecuteSweep(const std::vector<Command>& commands) {
    if (!sweep.active) {
      sweep.active = true;
      world->SetHeadRunning(true);
    }
    for (const Command& c : commands) {
      if (abort) return false;
      switch (c[0]) {
        case kJumpSpeed:
          params.jump_speed_mm_per_s = Mm(c[1]);
          break;
        case kJumpDelay:  // a parameter: the wait after every jump from here on
          sweep_jump_delay_s = (c[2] & 0x8000 ? -1.0 : 1.0) * c[1] * 1e-6;
          break;
        case kDelayTime:
          sweep.pending_s += c[1] * 10e-6;
          break;
        case kSetDaZWord:
          z_mm = options.z_units_per_mm > 0 ? (c[1] - 32768.0) / options.z_units_per_mm : 0.0;
          break;
        case kWritePortList:
          if (Rises(c) && !(ports_now & options.trigger_port)) {
            sweep.pulse_pending = true;
            sweep.to_pulse_s = sweep.pending_s;
          }
          ports_now = c[1];
          break;
        case kJumpTo:
        case kMarkTo: {  // the laser is off in a light list: a mark only moves the mirrors
          const auto xy = FromUnits(c[1], c[2], options);
          const Eigen::Vector3d q(xy[0], xy[1], z_mm);
          if (sweep.pulse_pending) {
            // The jump to the line and the settle pass first; then the pointer sweeps from the
            // line's start as the trigger rises.
            world->Advance(sweep.to_pulse_s);
            (void)world->StartPointerLine(sweep.at, q, params.jump_speed_mm_per_s);
            world->TriggerPulse();
            sweep.pending_s -= sweep.to_pulse_s;
            sweep.pulse_pending = false;
          }
          sweep.pending_s += (q - sweep.at).norm() / params.jump_speed_mm_per_s;
          if (c[0] == kJumpTo) sweep.pending_s += std::max(0.0, sweep_jump_delay_s);
          sweep.at = q;
          break;
        }
        case kEndOfList:  // the list's end: the sweep is over
          EndSweep();
          return true;
        default:
          break;
      }
    }
    return false;
  }

  // The sweep's list has run out (its end-of-list padding; or the host stopped it, cleared
  // the ports or reset the list): its last time on the clock, the head's clock handed back.
  // A sweep streamed in several packets goes on across them.
  void EndSweep() {
    if (!sweep.active) return;
    world->Advance(sweep.pending_s);
    world->SetHeadRunning(false);
    sweep = Sweep{};
  }

  double Mm(uint16_t speed_word) const { return speed_word / units_per_ms_per_mm_s; }

  // Runs a list on the head up to its end-of-list (true once executed; what follows it is not
  // the list). Called with the mutex held (light lists) or not (the runner): it touches the
  // shared state only through `shared`.
  bool Execute(const std::vector<Command>& commands, bool locked = true) {
    std::unique_lock<std::mutex> shared(mutex, std::defer_lock);
    if (!locked) shared.lock();
    uint16_t ports = log.ports;
    if (!locked && (sweep.active || std::any_of(commands.begin(), commands.end(),
                                                [&](const Command& c) { return Rises(c); }))) {
      ports_now = ports;
      shared.unlock();
      const bool ended = ExecuteSweep(commands);
      shared.lock();
      log.ports = ports_now;
      return ended;
    }
    // The laser emits only with its output enabled and the master oscillator open.
    const bool laser_enabled = log.laser_enabled && log.mo_open;
    if (!locked) shared.unlock();
    std::vector<sim::ListMove> moves;
    bool marks = false;
    bool ended = false;
    // Every parameter applies from its place in the list on: a change after moves runs the
    // moves before it with the values they had (the head settles there).
    const auto flush = [&] {
      if (moves.empty()) return;
      if (!marks && (ports & options.pointer_port) && moves.size() >= 2) return;  // a light list
      (void)world->ExecuteMarkingList(moves, params, &abort);
      moves.clear();
      marks = false;
    };
    const auto set = [&](double* field, double value) {
      if (*field == value) return;
      flush();
      *field = value;
    };
    std::vector<std::string> unknown;
    for (const Command& c : commands) {
      if (ended) break;
      switch (c[0]) {
        case kEndOfList:
          ended = true;
          break;
        case kReadyMark:
          break;
        case kDelayTime:
          if (moves.empty()) {
            world->Advance(c[1] * 10e-6);  // before the first move: the oscillator settles
          } else {
            params.mark_delay_us = c[1] * 10.0;  // after a mark sequence: its mark delay
          }
          break;
        case kWritePortList:
          ports = c[1];
          break;
        case kJumpSpeed:
          set(&params.jump_speed_mm_per_s, Mm(c[1]));
          break;
        case kMarkSpeed:
          set(&params.mark_speed_mm_per_s, Mm(c[1]));
          break;
        case kMarkCurrent:  // fibre, mopa
          set(&params.power_fraction, c[1] / 4095.0);
          break;
        case kQSwitchPeriod:  // fibre, mopa: 50 ns units
          if (c[1] > 0) set(&params.pulse_frequency_khz, 20000.0 / c[1]);
          break;
        case kMarkFreq:  // co2, uv: 100 ns units
          if (c[1] > 0) set(&params.pulse_frequency_khz, 10000.0 / c[1]);
          break;
        case kMarkPowerRatio: {  // co2, uv: 200 x power % / kHz
          const double percent = c[1] * params.pulse_frequency_khz / 200.0;
          const double power = options.power_invert ? 100.0 - percent : percent;
          set(&params.power_fraction, std::clamp(power / 100.0, 0.0, 1.0));
          break;
        }
        case kSetCo2Fpk:
        case kFiberPulseWidth:
          break;  // the simulated source has no first pulse or pulse shape
        case kLaserOnDelay:
          set(&params.laser_on_delay_us, c[1]);
          break;
        case kLaserOffDelay:
          set(&params.laser_off_delay_us, c[1]);
          break;
        case kJumpDelay:
          set(&params.jump_delay_us, c[1]);
          break;
        case kPolygonDelay:
          break;  // corners between marks: the simulated head has no corner model
        case kSetDaZWord:
          z_mm = options.z_units_per_mm > 0 ? (c[1] - 32768.0) / options.z_units_per_mm : 0.0;
          break;
        case kJumpTo:
        case kMarkTo: {
          const auto xy = FromUnits(c[1], c[2], options);
          // With the laser output disabled a mark moves the mirrors and nothing fires.
          const bool fire = c[0] == kMarkTo && laser_enabled;
          marks |= fire;
          moves.push_back({fire ? sim::ListMove::Kind::kMark : sim::ListMove::Kind::kJump,
                           Eigen::Vector3d(xy[0], xy[1], z_mm)});
          break;
        }
        default:
          unknown.push_back("list opcode " + Hex(c[0]) + " is not one the board knows");
          break;
      }
    }
    if (!locked) shared.lock();
    log.ports = ports;
    for (std::string& u : unknown) Reject(std::move(u));
    if (!locked) shared.unlock();
    if (moves.empty()) return ended;
    if (!marks && (ports & options.pointer_port) && moves.size() >= 2) {
      // A light list: the pointer sweeps between its first two points until stopped.
      (void)world->StartPointerLine(moves[0].to_in_galvo, moves[1].to_in_galvo,
                                    params.jump_speed_mm_per_s);
      return ended;
    }
    (void)world->ExecuteMarkingList(moves, params, &abort);
    return ended;
  }

  void Handle(const Command& c) {
    ++log.single_commands;
    switch (c[0]) {
      case kGetVersion:
        Reply({0x0001, 0x0000, 0x0000,
               static_cast<uint16_t>((running ? kStatusBusy : 0) | kStatusReady)});
        return;
      case kGetSerialNo:  // four words of serial, no status
        Reply({0x0e2c, 0x2026, 0x1127, 0x0001});
        return;
      case kReset:  // power-up state: no list, the modes to be set again, the laser off
        ++log.resets;
        buffer.clear();
        list_open = false;
        running = false;  // the runner has returned (Write joined it)
        starved = false;
        sweep_jump_delay_s = 0.0;
        z_mm = 0.0;
        world->StopPointer();
        startup_seen.clear();
        log.laser_enabled = false;
        log.mo_open = false;
        log.ports = 0;
        params = sim::MarkingParams{};
        if (!running) EndSweep();
        break;
      case kSetControlMode:
      case kSetLaserMode:
      case kSetDelayMode:
      case kSetTiming:
      case kSetStandby:
      case kSetFirstPulseKiller:
      case kSetPwmHalfPeriod:
      case kSetPwmPulseWidth:
      case kSetFpkParam2:
      case kSetFlyRes:
      case kEnableZ:
      case kWriteAnalogPort1:
      case kSetEndOfList:
        break;
      case kResetList:
        buffer.clear();
        list_open = false;
        if (!running) EndSweep();
        break;
      case kExecuteList:
        if (!Started()) {
          Reject(
              "ExecuteList before the board's start-up (Reset, correction table, modes): "
              "the list was not run");
          buffer.clear();
          break;
        }
        list_open = true;
        if (IsLightList(buffer)) {
          // The pointer starts sweeping within microseconds of the command, long before any
          // camera exposure: set it up before the command returns.
          std::vector<Command> commands;
          commands.swap(buffer);
          ++log.lists_executed;
          if (Execute(commands)) ++log.end_of_lists;
        } else {
          StartLocked();
        }
        break;
      case kStopExecute: {
        ++log.stops;
        abort = true;
        buffer.clear();
        list_open = false;
        running = false;  // the runner has returned (Write joined it); a starved list ends
        starved = false;
        EndSweep();  // the runner has stopped (Write joined it)
        world->StopPointer();
        break;
      }
      case kEnableLaser:
        log.laser_enabled = true;
        break;
      case kFiberSetMo:
        log.mo_open = c[1] != 0;
        break;
      case kDisableLaser:
        log.laser_enabled = false;
        break;
      case kWritePort:
        if (!running) EndSweep();
        log.ports = c[1];
        if (!(c[1] & options.pointer_port)) world->StopPointer();
        break;
      case kGotoXY:
        log.last_goto_distance = c[4];
        if (!running) {
          const auto xy = FromUnits(c[1], c[2], options);
          (void)world->MoveHead(Eigen::Vector3d(xy[0], xy[1], z_mm));
        }
        break;
      case kWriteCorTable:
        // A new table: until its last line the board corrects nothing (a blank one: never).
        log.correction.clear();
        log.correction_blank = c[1] == 0;
        world->ClearBoardCorrection(this);
        break;
      case kWriteCorLine: {
        const auto value = [](uint16_t w) {
          return w & 0x8000 ? -static_cast<int32_t>(w & 0x7FFF) : static_cast<int32_t>(w);
        };
        log.correction.push_back({value(c[1]), value(c[2])});
        if (log.correction.size() == 65 * 65) {
          // The whole table: from here on every position the board sends the head has been
          // through it (ApplyBoardTable: the documented convention).
          BoardCorrection table;
          table.offsets = log.correction;
          world->SetBoardCorrection(this, [table, o = options](const Eigen::Vector2d& command_mm) {
            return ApplyBoardTableMm(table, o, command_mm);
          });
        }
        return;  // the board does not answer a correction line
      }
      default:
        Reject("single opcode " + Hex(c[0]) + " is not one the board knows");
        break;
    }
    startup_seen.insert(c[0]);
    log.started = Started();
    Reply(static_cast<uint16_t>((running ? kStatusBusy : 0) | kStatusReady));
  }
};

SimBoard::SimBoard(std::shared_ptr<sim::SimWorld> world, BoardOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->world = std::move(world);
  impl_->options = options;
  impl_->units_per_ms_per_mm_s = 65536.0 / options.lens_mm / 1000.0;
}

SimBoard::~SimBoard() {
  impl_->abort = true;
  impl_->Join();
  impl_->world->ClearBoardCorrection(impl_.get());  // the head is no longer behind this board
}

Status SimBoard::Write(const uint8_t* data, size_t size) {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  if (size == kCommandBytes) {
    const Command c = DecodeCommand(data);
    if (c[0] == kStopExecute || c[0] == kReset) {
      // Stop (and a reset) waits for the head to come to rest (the runner sees the abort on
      // its next tick).
      impl_->abort = true;
      lock.unlock();
      impl_->Join();
      lock.lock();
    }
    impl_->Handle(c);
    return Status::Ok();
  }
  if (size == kPacketBytes) {
    ++impl_->log.packets;
    for (size_t k = 0; k < kPacketCommands; ++k) {
      impl_->buffer.push_back(DecodeCommand(data + k * kCommandBytes));
    }
    if (impl_->list_open) impl_->StartLocked();
    return Status::Ok();
  }
  return Status(StatusCode::kDeviceError,
                "simulated LMC board: a transfer of " + std::to_string(size) +
                    " bytes is neither a command (12) nor a list packet (3072)");
}

Status SimBoard::Read(uint8_t* data, size_t size) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  if (size != kReplyBytes || impl_->replies.empty()) {
    return Status(StatusCode::kDeviceError, "simulated LMC board: no reply pending (a read of " +
                                                std::to_string(size) + " bytes without a command)");
  }
  std::copy(impl_->replies.front().begin(), impl_->replies.front().end(), data);
  impl_->replies.pop_front();
  return Status::Ok();
}

SimBoardLog SimBoard::log() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->log;
}

}  // namespace insitu::hw::lmc
