// The Scanner on an LMC board: single commands answered by a status reply, lists streamed in
// packets and polled until the board is no longer busy.
#include <chrono>
#include <mutex>
#include <thread>

#include "insitu/hw/lmc.h"

namespace insitu::hw::lmc {
namespace {

class BoardScanner : public Scanner {
 public:
  BoardScanner(std::unique_ptr<Transport> transport, BoardOptions options)
      : transport_(std::move(transport)), options_(options) {}

  ~BoardScanner() override {
    // Leave the board safe: nothing running, the laser output off.
    (void)Single(kStopExecute);
    (void)Single(kDisableLaser);
  }

  ScannerInfo info() const override {
    ScannerInfo i;
    i.model = "BJJCZ LMC board (" + transport_->Describe() + ")";
    // The floor in ToUnits puts +lens/2 one unit past 0xFFFF: half the lens minus one unit.
    i.field_half_size_mm = 0.5 * options_.lens_mm * (1.0 - 2.0 / 65536.0);
    i.focus_range_mm = options_.focus == Focus::kDaZWord ? options_.focus_range_mm : 0.0;
    i.clock_us = 10.0;
    return i;
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
    INSITU_ASSIGN_OR_RETURN(auto commands, EncodeList(sweep, light, &position_, &z_word_));
    INSITU_RETURN_IF_ERROR(Single(kWritePort, options_.pointer_port).status());
    INSITU_RETURN_IF_ERROR(SendList(commands));
    pointer_on_ = true;
    return Status::Ok();
  }

  Status StopPointer() override {
    if (!pointer_on_) return Status::Ok();
    pointer_on_ = false;
    INSITU_RETURN_IF_ERROR(Single(kStopExecute).status());
    INSITU_RETURN_IF_ERROR(Single(kWritePort, 0).status());
    return Single(kResetList).status();
  }

  Status Arm() override {
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
    bool marks = false;
    for (const GalvoListEntry& e : list.entries) marks |= e.kind == GalvoListEntry::Kind::kMark;
    if (marks && !armed_)
      return FailedPrecondition("the list marks but the scan head is not armed");
    INSITU_RETURN_IF_ERROR(StopPointer());
    std::array<uint16_t, 2> position = position_;
    uint16_t z_word = z_word_;
    INSITU_ASSIGN_OR_RETURN(auto commands, EncodeList(list, options_, &position, &z_word));
    INSITU_RETURN_IF_ERROR(SendList(commands));
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
      if (control.abort != nullptr && control.abort->load()) {
        const Status stopped = Abort();
        if (!stopped.ok()) return stopped.Prefixed("aborting the list");
        return Status(StatusCode::kCancelled,
                      "list aborted: StopExecute sent, laser output disabled");
      }
      auto status = Single(kGetVersion);
      if (!status.ok()) {
        (void)Abort();
        return status.status().Prefixed("while the list ran");
      }
      if (!(*status & kStatusBusy)) break;
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (elapsed > options_.list_timeout_s) {
        (void)Abort();
        return Status(StatusCode::kDeviceError, "the board was still busy after " +
                                                    std::to_string(options_.list_timeout_s) +
                                                    " s: list aborted");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(options_.poll_ms));
    }
    position_ = position;
    z_word_ = z_word;
    if (control.progress) control.progress(1.0);
    return Status::Ok();
  }

 private:
  // One command and its status word. Errors: device_error from the transport.
  Result<uint16_t> Single(uint16_t op, uint16_t p1 = 0, uint16_t p2 = 0, uint16_t p3 = 0) {
    const std::vector<uint8_t> bytes = SingleCommand(op, p1, p2, p3);
    INSITU_RETURN_IF_ERROR(transport_->Write(bytes.data(), bytes.size()));
    uint8_t reply[kReplyBytes];
    INSITU_RETURN_IF_ERROR(transport_->Read(reply, sizeof reply));
    return static_cast<uint16_t>(reply[6] | (reply[7] << 8));
  }

  Status Goto(const Eigen::Vector3d& p) {
    INSITU_ASSIGN_OR_RETURN(const auto units, ToUnits(p.x(), p.y(), options_));
    INSITU_RETURN_IF_ERROR(Single(kGotoXY, units[0], units[1]).status());
    position_ = units;
    return Status::Ok();
  }

  // ResetList, the first packets each with SetEndOfList, ExecuteList, then the rest as the
  // board reports READY.
  Status SendList(const std::vector<Command>& commands) {
    const auto packets = Packets(commands);
    INSITU_RETURN_IF_ERROR(Single(kResetList).status());
    const size_t before =
        std::min(packets.size(), static_cast<size_t>(options_.packets_before_start));
    for (size_t i = 0; i < packets.size(); ++i) {
      if (i >= before) INSITU_RETURN_IF_ERROR(WaitReady());
      INSITU_RETURN_IF_ERROR(transport_->Write(packets[i].data(), packets[i].size()));
      INSITU_RETURN_IF_ERROR(Single(kSetEndOfList).status());
      if (i + 1 == before) INSITU_RETURN_IF_ERROR(Single(kExecuteList).status());
    }
    return Status::Ok();
  }

  Status WaitReady() {
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
      INSITU_ASSIGN_OR_RETURN(const uint16_t s, Single(kGetVersion));
      if (s & kStatusReady) return Status::Ok();
      if (std::chrono::steady_clock::now() - start > std::chrono::seconds(10)) {
        return Status(StatusCode::kDeviceError,
                      "the board did not take the next list packet within 10 s");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(options_.poll_ms));
    }
  }

  // StopExecute, laser output off, list reset: the board's way to stop at once.
  Status Abort() {
    INSITU_RETURN_IF_ERROR(Single(kStopExecute).status());
    armed_ = false;
    INSITU_RETURN_IF_ERROR(Single(kDisableLaser).status());
    return Single(kResetList).status();
  }

  std::unique_ptr<Transport> transport_;
  BoardOptions options_;
  bool armed_ = false;
  bool pointer_on_ = false;
  std::array<uint16_t, 2> position_{0x8000, 0x8000};
  uint16_t z_word_ = 0;  // unknown: the first point of a focus head sets it
};

}  // namespace

std::unique_ptr<Scanner> MakeScanner(std::unique_ptr<Transport> transport, BoardOptions options) {
  return std::make_unique<BoardScanner>(std::move(transport), options);
}

}  // namespace insitu::hw::lmc
