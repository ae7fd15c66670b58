// The Scanner on an LMC board: single commands answered by a status reply, lists streamed in
// packets and polled until the board is no longer busy.
#include <algorithm>
#include <chrono>
#include <mutex>
#include <thread>
#include <utility>

#include "hw/lmc/lmc.h"

namespace insitu::hw::lmc {
namespace {

class BoardScanner : public Scanner {
 public:
  BoardScanner(std::unique_ptr<Transport> transport, BoardOptions options, BoardCorrection uploaded,
               BoardIdentity identity)
      : transport_(std::move(transport)),
        options_(options),
        uploaded_(std::move(uploaded)),
        identity_(std::move(identity)) {}

  ~BoardScanner() override {
    // Leave the board safe: nothing running, the oscillator closed, the laser output off.
    (void)Abort();
  }

  ScannerInfo info() const override {
    ScannerInfo i;
    i.model = "BJJCZ LMC board (" + transport_->Describe() +
              (identity_.serial.empty() ? "" : ", " + identity_.Describe()) + ", " +
              SourceName(options_.source) + " source)";
    // The floor in ToUnits puts +lens/2 one unit past 0xFFFF: half the lens minus one unit.
    i.field_half_size_mm = 0.5 * options_.lens_mm * (1.0 - 2.0 / 65536.0);
    i.table_field_mm = options_.lens_mm;
    i.table_swap_xy = options_.swap_xy;
    i.table_flip_x = options_.flip_x;
    i.table_flip_y = options_.flip_y;
    i.focus_range_mm = options_.focus == Focus::kDaZWord ? options_.focus_range_mm : 0.0;
    i.clock_us = 10.0;
    i.trigger_output = options_.trigger_port != 0;
    return i;
  }

  bool DriveCommand(const Eigen::Vector2d& command_mm, Eigen::Vector2d* drive_mm) const override {
    *drive_mm = ApplyBoardTableMm(uploaded_, options_, command_mm);
    return true;
  }

  Status StartPointerLine(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                          double speed_mm_per_s) override {
    if (!(speed_mm_per_s > 0)) return InvalidArgument("pointer speed must be > 0");
    INSITU_RETURN_IF_ERROR(StopPointer());
    // The pointer sweeps as a light list: jumps back and forth with the laser off and the
    // pointer port on, as many as one list holds; the board repeats nothing by itself.
    GalvoList sweep;
    sweep.jump_speed_mm_per_s = speed_mm_per_s;
    sweep.laser_power = 0.0;
    for (int k = 0; k < 200; ++k) {
      sweep.entries.push_back({GalvoListEntry::Kind::kJump, to});
      sweep.entries.push_back({GalvoListEntry::Kind::kJump, from});
    }
    BoardOptions light = options_;
    light.list_ports = options_.pointer_port;
    light.open_mo_delay_us = 0.0;
    INSITU_RETURN_IF_ERROR(Goto(from));
    std::array<uint16_t, 2> position = position_;
    uint16_t z_word = z_word_;
    INSITU_ASSIGN_OR_RETURN(auto commands, EncodeList(sweep, light, &position, &z_word));
    INSITU_RETURN_IF_ERROR(Single(kWritePort, options_.pointer_port).status());
    pointer_on_ = true;  // from here on, stopping it is needed
    const Status sent = SendList(commands, ListControl{});
    if (!sent.ok()) {
      (void)StopPointer();
      return sent;
    }
    position_ = position;
    z_word_ = z_word;
    return Status::Ok();
  }

  Status StopPointer() override {
    if (!pointer_on_) return Status::Ok();
    INSITU_RETURN_IF_ERROR(Single(kStopExecute).status());
    INSITU_RETURN_IF_ERROR(Single(kWritePort, 0).status());
    INSITU_RETURN_IF_ERROR(Single(kResetList).status());
    pointer_on_ = false;
    z_word_ = 0;  // where the sweep was stopped is not known
    return Status::Ok();
  }

  std::string ReceivedList() const override { return received_; }

  Status Arm() override {
    received_.clear();  // a job's list to come: none received yet
    INSITU_RETURN_IF_ERROR(Single(kEnableLaser).status());
    armed_ = true;
    return Status::Ok();
  }
  Status Disarm() override {
    armed_ = false;
    return Single(kDisableLaser).status();
  }
  bool armed() const override { return armed_; }

 protected:
  Status RunList(const GalvoList& list, const ListControl& control) override {
    received_.clear();
    const bool marks = list.HasMarks();
    INSITU_RETURN_IF_ERROR(StopPointer());
    std::array<uint16_t, 2> position = position_;
    uint16_t z_word = z_word_;
    INSITU_ASSIGN_OR_RETURN(auto commands, EncodeList(list, options_, &position, &z_word));
    const double estimate_s = Duration(list);
    // What the board receives: the commands and the end-of-list Packets adds.
    received_ = FormatCommands(commands);
    if (commands.empty() || commands.back()[0] != kEndOfList) {
      received_ += FormatCommands({Command{kEndOfList, 0, 0, 0, 0, 0}});
    }
    // From here on every way out leaves the board stopped and the oscillator closed.
    z_word_ = 0;  // unknown until the list has run
    if (marks) INSITU_RETURN_IF_ERROR(Single(kFiberSetMo, 1).status());
    INSITU_RETURN_IF_ERROR(Run(commands, control, estimate_s));
    if (marks) INSITU_RETURN_IF_ERROR(Single(kFiberSetMo, 0).status());
    // The list set its ports (list_ports): off again, as they were before it.
    INSITU_RETURN_IF_ERROR(Single(kWritePort, 0).status());
    position_ = position;
    z_word_ = z_word;
    if (control.progress) control.progress(1.0);
    return Status::Ok();
  }

  // One list on the board: the pointer on, the trigger output pulsed once per line.
  Status RunSweep(const TriggeredSweep& sweep, const ListControl& control) override {
    INSITU_RETURN_IF_ERROR(StopPointer());
    std::array<uint16_t, 2> position = position_;
    uint16_t z_word = z_word_;
    INSITU_ASSIGN_OR_RETURN(auto commands,
                            EncodeTriggeredSweep(sweep, options_, &position, &z_word));
    z_word_ = 0;
    const double estimate_s =
        static_cast<double>(sweep.lines.size()) * (sweep.settle_s + sweep.dwell_s);
    const Status ran = Run(commands, control, estimate_s);
    // The list leaves the pointer port on: off with the sweep, however it ended.
    const Status off = Single(kWritePort, 0).status();
    INSITU_RETURN_IF_ERROR(ran);
    INSITU_RETURN_IF_ERROR(off);
    position_ = position;
    z_word_ = z_word;
    if (control.progress) control.progress(1.0);
    return Status::Ok();
  }

 private:
  // One command and its status word. Errors: device_error from the transport.
  Result<uint16_t> Single(uint16_t op, uint16_t p1 = 0, uint16_t p2 = 0, uint16_t p3 = 0) {
    return Single(SingleCommand(op, p1, p2, p3));
  }
  Result<uint16_t> Single(const std::vector<uint8_t>& bytes) {
    INSITU_ASSIGN_OR_RETURN(const auto words, Query(*transport_, bytes));
    return words[3];
  }

  // Streams `commands` and waits until the board is no longer busy; the list's time estimate
  // stands in for progress. Every failure and control.abort leave the board stopped (Abort).
  Status Run(const std::vector<Command>& commands, const ListControl& control,
             double estimate_s) {
    run_estimate_s_ = estimate_s;
    const Status sent = SendList(commands, control);
    if (!sent.ok()) return Stopped(sent);
    const Status done = WaitFor(Until::kIdle, &control);
    if (!done.ok()) return Stopped(done);
    return Status::Ok();
  }

  Status Goto(const Eigen::Vector3d& p) {
    INSITU_ASSIGN_OR_RETURN(const auto units, ToUnits(p.x(), p.y(), options_));
    INSITU_RETURN_IF_ERROR(Single(GotoXY(position_, units)).status());
    position_ = units;
    return Status::Ok();
  }

  // ResetList, then every packet once the board reports READY, each with SetEndOfList, and
  // ExecuteList after the first packets_before_start of them. The abort flag is checked before
  // every packet.
  Status SendList(const std::vector<Command>& commands, const ListControl& control) {
    const auto packets = Packets(commands);
    run_start_ = std::chrono::steady_clock::now();
    INSITU_RETURN_IF_ERROR(Single(kResetList).status());
    const size_t before =
        std::min(packets.size(), static_cast<size_t>(options_.packets_before_start));
    for (size_t i = 0; i < packets.size(); ++i) {
      INSITU_RETURN_IF_ERROR(WaitFor(Until::kReady, &control));
      INSITU_RETURN_IF_ERROR(transport_->Write(packets[i].data(), packets[i].size()));
      INSITU_RETURN_IF_ERROR(Single(kSetEndOfList).status());
      if (i + 1 == before) INSITU_RETURN_IF_ERROR(Single(kExecuteList).status());
    }
    return Status::Ok();
  }

  // The list's time on the head: moves at their speeds plus the delays (for progress only).
  static double Duration(const GalvoList& list) {
    double s = 0.0;
    Eigen::Vector3d at = Eigen::Vector3d::Zero();
    for (const GalvoListEntry& e : list.entries) {
      const bool mark = e.kind == GalvoListEntry::Kind::kMark;
      s += (e.to_in_galvo - at).norm() /
           (mark ? list.mark_speed_mm_per_s : list.jump_speed_mm_per_s);
      s += (mark ? list.mark_delay_us : list.jump_delay_us) * 1e-6;
      at = e.to_in_galvo;
    }
    return s;
  }

  // Stops the board and makes it safe after `why`, which is returned (with the stop's own
  // failure, if any).
  Status Stopped(const Status& why) {
    const Status stopped = Abort();
    if (stopped.ok()) return why;
    return Status(why.code(),
                  why.message() + "; stopping the board also failed: " + stopped.message());
  }

  enum class Until { kReady, kIdle };
  // Polls the board's status every poll_ms until it is READY for the next packet (kReady) or no
  // longer BUSY (kIdle). However long a list keeps the board busy, the wait goes on (a long
  // list runs for hours; list_timeout_s > 0 bounds it), with progress from the list's time
  // estimate, and control->abort is looked at before every poll: cancelled within one poll.
  // A board that reports neither READY nor BUSY for a second while a packet waits has lost the
  // list. `limit_s` > 0: the whole wait's bound (Abort's flush).
  Status WaitFor(Until until, const ListControl* control, double limit_s = 0.0) {
    const auto start = std::chrono::steady_clock::now();
    auto stuck_since = start;
    for (;;) {
      if (control != nullptr && control->abort != nullptr && control->abort->load()) {
        return Status(StatusCode::kCancelled,
                      "list aborted: StopExecute sent, oscillator closed, laser output disabled");
      }
      INSITU_ASSIGN_OR_RETURN(const uint16_t status, Single(kGetVersion));
      const bool busy = (status & kStatusBusy) != 0;
      if (until == Until::kReady ? (status & kStatusReady) != 0 : !busy) return Status::Ok();
      const auto now = std::chrono::steady_clock::now();
      const double waited = std::chrono::duration<double>(now - start).count();
      if (limit_s > 0 && waited > limit_s) {
        return Status(StatusCode::kDeviceError, "the board stayed busy after its list was stopped");
      }
      const double running = std::chrono::duration<double>(now - run_start_).count();
      if (limit_s == 0 && options_.list_timeout_s > 0 && running > options_.list_timeout_s) {
        return Status(StatusCode::kDeviceError, "the board was still busy after list_timeout_s (" +
                                                    std::to_string(options_.list_timeout_s) +
                                                    " s)");
      }
      if (busy) stuck_since = now;
      if (until == Until::kReady &&
          std::chrono::duration<double>(now - stuck_since).count() > 1.0) {
        return Status(StatusCode::kDeviceError,
                      "the board neither took the next list packet nor ran the list for 1 s "
                      "(status word " +
                          std::to_string(status) + ")");
      }
      // The board tells no progress: the list's own time estimate stands in, short of 1,
      // about every 100 ms.
      if (control != nullptr && control->progress && run_estimate_s_ > 0 &&
          now - last_progress_ >= std::chrono::milliseconds(100)) {
        control->progress(std::min(0.99, running / run_estimate_s_));
        last_progress_ = now;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(options_.poll_ms));
    }
  }

  // StopExecute, the oscillator closed, the laser output off, the list reset: every one tried
  // whatever the others did; the first failure is returned. Then, on a board that answered,
  // the flush an idle board expects (an empty list: one packet of end-of-list, executed, so
  // the next list starts on a list memory that ends) and the ports off.
  Status Abort() {
    armed_ = false;
    z_word_ = 0;
    Status first = Status::Ok();
    const std::pair<uint16_t, uint16_t> steps[] = {
        {kStopExecute, 0}, {kFiberSetMo, 0}, {kDisableLaser, 0}, {kResetList, 0}};
    for (const auto& [op, p1] : steps) {
      const Status s = Single(op, p1).status();
      if (!s.ok() && first.ok()) first = s;
    }
    if (!first.ok()) return first;
    const std::vector<uint8_t> empty = Packets({}).front();
    INSITU_RETURN_IF_ERROR(transport_->Write(empty.data(), empty.size()));
    for (uint16_t op : {kSetEndOfList, kExecuteList}) INSITU_RETURN_IF_ERROR(Single(op).status());
    // The empty list takes the board a tick; idle again within half a second or named.
    INSITU_RETURN_IF_ERROR(WaitFor(Until::kIdle, nullptr, 0.5));
    pointer_on_ = false;
    return Single(kWritePort, 0).status();
  }

  std::unique_ptr<Transport> transport_;
  BoardOptions options_;
  BoardCorrection uploaded_;  // what the board was given when it opened (empty: none)
  BoardIdentity identity_;
  std::string received_;  // the last marking list as the board received it (ReceivedList)
  // The list running: when it started streaming and its time estimate (progress).
  std::chrono::steady_clock::time_point run_start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_progress_{};
  double run_estimate_s_ = 0.0;
  bool armed_ = false;
  bool pointer_on_ = false;
  std::array<uint16_t, 2> position_{0x8000, 0x8000};
  uint16_t z_word_ = 0;  // unknown: the first point of a focus head sets it
};

}  // namespace

std::unique_ptr<Scanner> MakeScanner(std::unique_ptr<Transport> transport, BoardOptions options,
                                     BoardCorrection uploaded, BoardIdentity identity) {
  return std::make_unique<BoardScanner>(std::move(transport), options, std::move(uploaded),
                                        std::move(identity));
}

Result<std::unique_ptr<Scanner>> OpenScanner(std::unique_ptr<Transport> transport,
                                             BoardOptions options, BoardCorrection table) {
  INSITU_ASSIGN_OR_RETURN(BoardIdentity identity, StartUp(*transport, options, table));
  return MakeScanner(std::move(transport), options, std::move(table), std::move(identity));
}

}  // namespace insitu::hw::lmc
