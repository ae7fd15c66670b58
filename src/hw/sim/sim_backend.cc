#include "insitu/hw/sim_backend.h"

#include <utility>

namespace insitu::hw {
namespace {

class SimScanner : public Scanner {
 public:
  explicit SimScanner(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}

  ScannerInfo info() const override {
    const auto& sh = world_->options().scan_head;
    // Its trigger output is there; whether a camera listens is the camera's (head_trigger).
    return {"simulated 3D scan head", sh.field_half_size_mm, sh.focus_range_mm, sh.clock_us,
            /*trigger_output=*/true};
  }
  // A head driven linearly (no correction of its own) gets the command as it is.
  bool DriveCommand(const Eigen::Vector2d& command_mm, Eigen::Vector2d* drive_mm) const override {
    if (world_->options().scan_head.own_correction) return false;
    *drive_mm = command_mm;
    return true;
  }
  Status StartPointerLine(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                          double speed_mm_per_s) override {
    INSITU_RETURN_IF_ERROR(InjectedFault());
    return world_->StartPointerLine(from, to, speed_mm_per_s);
  }
  Status StopPointer() override {
    world_->StopPointer();
    return Status::Ok();
  }
  Status Arm() override {
    armed_ = true;
    return Status::Ok();
  }
  Status Disarm() override {
    armed_ = false;
    return Status::Ok();
  }
  bool armed() const override { return armed_; }

 protected:
  Status RunList(const GalvoList& list, const ListControl& control) override {
    INSITU_RETURN_IF_ERROR(InjectedFault());
    std::vector<sim::ListMove> moves;
    for (const GalvoListEntry& e : list.entries) {
      const bool mark = e.kind == GalvoListEntry::Kind::kMark;
      moves.push_back(
          {mark ? sim::ListMove::Kind::kMark : sim::ListMove::Kind::kJump, e.to_in_galvo});
    }
    sim::MarkingParams params;
    params.jump_speed_mm_per_s = list.jump_speed_mm_per_s;
    params.mark_speed_mm_per_s = list.mark_speed_mm_per_s;
    params.power_fraction = list.laser_power;
    params.pulse_frequency_khz = list.laser_frequency_khz;
    params.laser_on_delay_us = list.laser_on_delay_us;
    params.laser_off_delay_us = list.laser_off_delay_us;
    params.jump_delay_us = list.jump_delay_us;
    params.mark_delay_us = list.mark_delay_us;
    return world_->ExecuteMarkingList(moves, params, control.abort, control.progress);
  }

  // Line by line on the head's clock: start the sweep, settle, pulse, dwell.
  Status RunSweep(const TriggeredSweep& sweep, const ListControl& control) override {
    struct Running {  // the pointer off and the clock handed back, whatever happens
      sim::SimWorld* world;
      ~Running() {
        world->StopPointer();
        world->SetHeadRunning(false);
      }
    } running{world_.get()};
    world_->SetHeadRunning(true);  // first: a camera waiting for a pulse learns of a fault
    INSITU_RETURN_IF_ERROR(InjectedFault());
    const size_t n = sweep.lines.size();
    for (size_t i = 0; i < n; ++i) {
      if (control.abort != nullptr && control.abort->load()) {
        return Status(StatusCode::kCancelled,
                      "sweep aborted before line " + std::to_string(i) + ", the pointer is off");
      }
      INSITU_RETURN_IF_ERROR(
          world_->StartPointerLine(sweep.lines[i].first, sweep.lines[i].second,
                                   sweep.speed_mm_per_s));
      world_->Advance(sweep.settle_s);
      world_->TriggerPulse();
      world_->Advance(sweep.dwell_s);
      if (control.progress) control.progress(static_cast<double>(i + 1) / n);
    }
    return Status::Ok();
  }

 private:
  // The injected scanner error (world faults): the head stops, the laser is off.
  Status InjectedFault() {
    const int at = world_->options().faults.scanner_error_at_command;
    if (at >= 0 && commands_++ == at) {
      world_->StopPointer();
      armed_ = false;
      return Status(StatusCode::kDeviceError,
                    "scan head error: servo fault on the X mirror (injected)");
    }
    return Status::Ok();
  }

  std::shared_ptr<sim::SimWorld> world_;
  bool armed_ = false;
  int commands_ = 0;
};

class SimCamera : public Camera {
 public:
  explicit SimCamera(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  CameraInfo info() const override {
    const auto& c = world_->options().camera;
    return {c.model, c.serial, c.width_px, c.height_px, c.bit_depth};
  }
  Status SetExposure(double exposure_us) override { return world_->SetExposure(exposure_us); }
  Status SetGain(double gain_db) override { return world_->SetGain(gain_db); }
  Status SetBinning(int binning) override { return world_->SetBinning(binning); }
  bool head_triggered() const override { return world_->options().camera.head_trigger; }
  Status StartTriggered() override {
    if (!head_triggered()) return Camera::StartTriggered();
    world_->ArmTrigger(true);
    triggered_ = true;
    return Status::Ok();
  }
  Status StopTriggered() override {
    world_->ArmTrigger(false);
    triggered_ = false;
    return Status::Ok();
  }
  double max_frame_rate_hz() const override { return world_->MaxFrameRateHz(); }
  void WakeTriggered() override { world_->HeadFailed(); }

 protected:
  Status ApplyRegion(int first_row, int rows) override {
    return world_->SetRegion(first_row, rows);
  }
  // Injected faults as a GigE camera shows them: no frame at all (a timeout), a frame that
  // lost packets on the wire (the stream reports it incomplete), or one whose payload does
  // not match its header (delivered: Camera::Grab's check catches it).
  Result<Frame> GrabFrame() override {
    const sim::FaultOptions& faults = world_->options().faults;
    const int n = frames_++;
    if (n == faults.camera_timeout_at_frame) {
      world_->Advance(1.0);  // the timeout's wait
      return Status(StatusCode::kDeviceError, "camera timeout: no frame within 1000 ms (injected)");
    }
    // Triggered: the frame the head's pulse exposed. 60 s of this computer's time: the
    // simulator renders a frame in well under one, even on a loaded machine.
    INSITU_ASSIGN_OR_RETURN(Frame frame, triggered_ ? world_->TakeTriggered(60.0) : world_->Grab());
    if (n == faults.camera_drop_frame_at) {
      return Status(StatusCode::kDeviceError,
                    "camera frame " + std::to_string(frame.sequence) +
                        " incomplete: 412 of its 2187 packets lost on the link (injected)");
    }
    if (n == faults.camera_corrupt_frame_at) {
      frame.bytes.resize(frame.bytes.size() / 3);  // the trailer came early
    }
    return frame;
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
  int frames_ = 0;
  bool triggered_ = false;
};

class SimCoaxialCamera : public Camera {
 public:
  explicit SimCoaxialCamera(std::shared_ptr<sim::SimWorld> world)
      : world_(std::move(world)),
        exposure_us_(world_->options().scan_head.coaxial.exposure_ms * 1e3) {}
  CameraInfo info() const override {
    const auto& c = world_->options().scan_head.coaxial;
    return {c.model, c.serial, c.width_px, c.height_px, 8};
  }
  Status SetExposure(double exposure_us) override {
    if (!(exposure_us >= 10.0 && exposure_us <= 1e6)) {
      return OutOfRange("coaxial exposure " + std::to_string(exposure_us) +
                        " us is outside the camera's range [10, 1e6] us");
    }
    exposure_us_ = exposure_us;
    return Status::Ok();
  }
  Status SetGain(double gain_db) override {
    if (gain_db != 0.0) return OutOfRange("the coaxial camera has a fixed gain of 0 dB");
    return Status::Ok();
  }
  Status SetBinning(int binning) override {
    if (binning != 1) return OutOfRange("the coaxial camera does not bin");
    return Status::Ok();
  }

 protected:
  Result<Frame> GrabFrame() override { return world_->GrabCoaxial(exposure_us_); }

 private:
  std::shared_ptr<sim::SimWorld> world_;
  double exposure_us_;
};

class SimStage : public Stage {
 public:
  explicit SimStage(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  double min_z_mm() const override { return world_->options().stage.min_z_mm; }
  double max_z_mm() const override { return world_->options().stage.max_z_mm; }
  Result<double> Position() const override { return world_->stage_commanded_z(); }
  Status MoveTo(double z_mm) override {
    if (world_->options().faults.stage_stuck) {
      world_->Advance(10.0);
      return Status(
          StatusCode::kDeviceError,
          "stage did not arrive at z = " + std::to_string(z_mm) + " mm within 10 s (injected)");
    }
    return world_->MoveStage(z_mm);
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
};

class SimClock : public MachineClock {
 public:
  explicit SimClock(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  double Now() const override { return world_->now_s(); }
  void SleepFor(double seconds) override { world_->Advance(seconds); }
  void Waited(double wall_seconds) override {
    if (wall_seconds > 0) world_->Advance(wall_seconds);
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
};

class SimOperator : public Operator {
 public:
  explicit SimOperator(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  Status PlaceBoard(int view, int) override { return world_->PlaceBoard(view); }
  Status RemoveBoard() override {
    world_->RemoveBoard();
    return Status::Ok();
  }
  Status PlaceBoardOnPlate() override { return world_->PlaceBoardOnPlate(); }
  Status FreshPlate() override {
    world_->FreshPlate();
    return Status::Ok();
  }
  Status ClearTable() override {
    world_->RemovePart();
    return Status::Ok();
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
};

// The gantry: x, y, z and C; no A axis on this machine.
class SimAxis : public Axis {
 public:
  explicit SimAxis(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  AxisInfo info() const override {
    const sim::GantryOptions& g = world_->options().gantry;
    AxisInfo i;
    i.model = g.model;
    i.min = {g.travel_min_mm[0], g.travel_min_mm[1], g.travel_min_mm[2], 0.0, -g.c_travel_deg};
    i.max = {g.travel_max_mm[0], g.travel_max_mm[1], g.travel_max_mm[2], 0.0, g.c_travel_deg};
    i.speed_mm_per_s = g.speed_mm_per_s;
    i.encoder_counts_per_mm = g.encoder_counts_per_mm;
    return i;
  }
  Result<AxisPose> Position() const override {
    const std::array<double, 4> p = world_->gantry_position();
    return AxisPose{p[0], p[1], p[2], 0.0, p[3]};
  }
  Status MoveTo(const AxisPose& pose) override {
    INSITU_RETURN_IF_ERROR(CheckTravel(pose, info()));
    return world_->MoveGantry({pose.x_mm, pose.y_mm, pose.z_mm, pose.c_deg});
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
};

class SimProfiler : public Profiler {
 public:
  explicit SimProfiler(std::shared_ptr<sim::SimWorld> world) : world_(std::move(world)) {}
  ProfilerInfo info() const override {
    const sim::ProfilerOptions& o = world_->options().profiler;
    ProfilerInfo i;
    i.model = o.model;
    i.serial = o.serial;
    i.points = o.points;
    i.x_spacing_mm = o.x_spacing_mm;
    i.x_start_mm = -0.5 * (o.points - 1) * o.x_spacing_mm;
    i.z_min_mm = o.z_min_mm;
    i.z_max_mm = o.z_max_mm;
    i.z_resolution_mm = o.z_resolution_mm;
    i.max_rate_hz = o.max_rate_hz;
    return i;
  }
  Status SetExposure(double exposure_us) override {
    return world_->SetProfilerExposure(exposure_us);
  }

 protected:
  Result<RangeProfile> GrabProfile() override {
    const int stop = world_->options().faults.profiler_stop_at_profile;
    if (stop >= 0 && grabbed_ >= stop) {
      world_->Advance(1.0);
      return Status(StatusCode::kDeviceError,
                    "line profiler: no profile within 1 s of the trigger (injected: it stopped "
                    "sending after " + std::to_string(stop) + " profiles)");
    }
    ++grabbed_;
    INSITU_ASSIGN_OR_RETURN(sim::SimWorld::ProfileShot shot, world_->GrabProfile());
    const ProfilerInfo i = info();
    RangeProfile p;
    p.x_start_mm = i.x_start_mm;
    p.x_spacing_mm = i.x_spacing_mm;
    p.z_mm = std::move(shot.z_mm);
    p.encoder = shot.encoder;
    p.sequence = shot.sequence;
    p.timestamp_s = shot.t_s;
    return p;
  }

 private:
  std::shared_ptr<sim::SimWorld> world_;
  int grabbed_ = 0;
};

}  // namespace

Machine MakeSimMachine(std::shared_ptr<sim::SimWorld> world) {
  Machine m;
  m.scanner = std::make_unique<SimScanner>(world);
  m.camera = std::make_unique<SimCamera>(world);
  if (world->options().scan_head.coaxial.present) {
    m.coaxial = std::make_unique<SimCoaxialCamera>(world);
  }
  m.stage = std::make_unique<SimStage>(world);
  m.clock = std::make_unique<SimClock>(world);
  m.person = std::make_unique<SimOperator>(world);
  if (world->options().gantry.present) m.axis = std::make_unique<SimAxis>(world);
  if (world->options().profiler.present) m.profiler = std::make_unique<SimProfiler>(world);
  return m;
}

}  // namespace insitu::hw
