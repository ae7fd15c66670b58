// The simulated machine: scan head, camera, Z stage and part, on one virtual clock.
//
// The hw sim backends (src/hw/sim) drive a SimWorld exactly as the real backends drive a
// scan head, a camera and a stage: commands in, frames out. Nothing here is visible to the
// reconstruction except through those interfaces; the truth accessors at the bottom exist
// for tests that measure the algorithms against reality.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/core/frame.h"
#include "insitu/core/status.h"
#include "insitu/sim/camera_model.h"
#include "insitu/sim/scan_optics.h"
#include "insitu/sim/scene.h"
#include "insitu/sim/world_options.h"

namespace insitu::sim {

// One point of a galvo list as the head executes it (galvo frame, mm).
struct ListMove {
  enum class Kind { kJump, kMark };
  Kind kind = Kind::kJump;
  Eigen::Vector3d to_in_galvo = Eigen::Vector3d::Zero();
};

// How a list is run: speeds, the marking laser's power and pulse rate, and the RTC delays
// (laser on after a mark sequence starts, off after it ends; the head holds still after jumps
// and after a mark sequence for the mirrors to settle). Delays must be >= 0.
struct MarkingParams {
  double jump_speed_mm_per_s = 5000.0;
  double mark_speed_mm_per_s = 1000.0;
  double power_fraction = 0.5;
  double pulse_frequency_khz = 30.0;
  double laser_on_delay_us = 0.0;
  double laser_off_delay_us = 0.0;
  double jump_delay_us = 0.0;
  double mark_delay_us = 0.0;
};

// One pulse of the marking laser where it hit (truth, for tests and the simulated imagers):
// the crater's centre, its diameter (0 if the fluence stayed under the surface's ablation
// threshold), and how far the surface was from the beam waist along the beam (+: beyond it).
struct MarkPulse {
  double t_s = 0.0;  // virtual time of the pulse
  Eigen::Vector3d point_in_world = Eigen::Vector3d::Zero();
  double diameter_mm = 0.0;
  double defocus_mm = 0.0;
  double beam_radius_mm = 0.0;  // 1/e^2 radius of the beam on the surface
  bool on_part = false;
};

// The last list the head aborted (truth, for tests): when it started, when it would have
// ended, the clock tick at which the head saw the abort flag, and the wall-clock instant it did.
struct ListAbortTruth {
  bool aborted = false;
  double list_start_s = 0.0;
  double list_end_s = 0.0;  // had it run to the end
  double seen_at_s = 0.0;
  std::chrono::steady_clock::time_point seen_wall;
};

class MarkMap;
}  // namespace insitu::sim

namespace insitu::fit {
class ModelExtension;
}  // namespace insitu::fit

namespace insitu::sim {

// What the camera saw in the last frame, from the simulator's side: for tests only.
struct FrameTruth {
  // Image position (pixels of the delivered frame) of every visible beam-centre sample.
  std::vector<Eigen::Vector2d> beam_pixels;
  // World point of every such sample (surface hit by the chief ray).
  std::vector<Eigen::Vector3d> beam_points_in_world;
  int samples = 0;           // beam samples in the exposure
  int occluded_samples = 0;  // hidden from the camera by the part
  double peak_electrons = 0.0;
};

class SimWorld {
 public:
  // `options` must be valid (WorldOptions::Validate()).
  explicit SimWorld(const WorldOptions& options);
  ~SimWorld();
  SimWorld(const SimWorld&) = delete;
  SimWorld& operator=(const SimWorld&) = delete;

  // Virtual clock, seconds since power-on.
  double now_s() const;
  void Advance(double seconds);

  // Scan head. Positions in the galvo frame, mm; z is the focus height.
  // The pointer sweeps back and forth from `from` to `to` until stopped.
  Status StartPointerLine(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                          double speed_mm_per_s);
  void StopPointer();
  // Runs a list with the marking laser, blocking in virtual time: the command moves at the
  // list's speeds on the head's clock, the mirrors follow with their tracking lag, and every
  // laser pulse while the laser is on ablates a crater where the beam meets the surface (its
  // diameter from the pulse fluence at the beam radius there: D^2 = 2 w^2 ln(F0 / F_th)).
  // The head polls `abort` (may be null) on every tick: once it is set the laser goes off at
  // that tick, the mirrors stop where the command was, and the call returns cancelled.
  // `progress` (may be empty) gets the fraction of the list's time done about every 100 ms
  // of list time.
  Status ExecuteMarkingList(const std::vector<ListMove>& moves, const MarkingParams& params,
                            const std::atomic<bool>* abort = nullptr,
                            const std::function<void(double)>& progress = {});
  // Moves the mirrors and the focus to a point with every beam off (a jump), and waits for
  // them to settle: where the coaxial camera then looks.
  Status MoveHead(const Eigen::Vector3d& point_in_galvo);
  // Where the head would put the chief ray for a command (after its correction table).
  bool CommandToAngles(const Eigen::Vector3d& point_in_galvo, MirrorAngles* angles) const;
  // A board between the host and the head (an LMC board) applies its correction table to
  // every command on the head's clock before the head gets it (galvo frame, mm, z unchanged);
  // empty: none. The emulated board `owner` sets it when a table has been uploaded; Clear
  // removes it only if that board set the one in place (several boards may come and go on one
  // world).
  void SetBoardCorrection(const void* owner,
                          std::function<Eigen::Vector2d(const Eigen::Vector2d&)> correction);
  void ClearBoardCorrection(const void* owner);

  // Z stage.
  Status MoveStage(double z_mm);
  double stage_z() const;            // where the plate's top really is
  double stage_commanded_z() const;  // what the stage reports (stage.scale_error_ppm)

  // The operator puts the calibration board at pose `index` of board.poses (modulo their
  // number). Errors: failed_precondition if the world has no board.
  Status PlaceBoard(int index);
  void RemoveBoard();
  // The operator lays the board flat on the stage plate at board.plate_pose (it rides on the
  // stage). Errors: failed_precondition if the world has no board.
  Status PlaceBoardOnPlate();
  // The operator puts a fresh sacrificial plate on the stage: every mark made so far is gone.
  void FreshPlate();
  // The operator takes the part off the stage.
  void RemovePart();
  int board_pose_count() const;

  // Camera.
  Status SetExposure(double exposure_us);
  Status SetGain(double gain_db);
  Status SetBinning(int binning);
  // Rows [first_row, first_row + rows) of the full sensor (rows 0: all), rounded out to the
  // binning; frames then hold only those rows (Frame::offset_y) and travel the link faster.
  Status SetRegion(int first_row, int rows);
  int binning() const;
  double exposure_us() const;
  // Exposes from now for the exposure time (the clock advances) and returns the frame.
  Result<Frame> Grab();
  // Frames per second the camera keeps at its exposure, binning and region: it exposes the
  // next frame while the last crosses the link, so 1 / max(exposure, link time).
  double MaxFrameRateHz() const;

  // The camera's trigger input, wired to the scan head's output (camera.head_trigger; without
  // it arming does nothing). While armed each pulse exposes a frame from that instant; frames
  // cross the link one after another and wait in order for TakeTriggered. A pulse while the
  // camera still exposes the last frame is ignored and counted, as a real camera ignores it.
  void ArmTrigger(bool armed);
  // The head's trigger output rises now.
  void TriggerPulse();
  // The head runs a triggered sweep: while it runs the clock is the head's, and TakeTriggered
  // waits for it to pass a frame's arrival; once it has stopped TakeTriggered advances the
  // clock to the arrival itself.
  void SetHeadRunning(bool running);
  // The next triggered frame once it has arrived (before the head has started, it waits for
  // it). Errors: device_error when none will come (the head has run and stopped and none
  // waits: its message counts the ignored pulses), or none within `wall_timeout_s` of this
  // computer's time.
  Result<Frame> TakeTriggered(double wall_timeout_s);
  int ignored_pulses() const;
  // The head's sweep failed (possibly before it started): no pulse will come, a waiting
  // TakeTriggered returns now.
  void HeadFailed();

  // The scan head's coaxial camera: exposes for `exposure_us` around where the head points,
  // sharp at the dynamic-focus height (the clock advances). 8-bit frame.
  // Errors: failed_precondition if the head has no coaxial camera; out_of_range exposure.
  Result<Frame> GrabCoaxial(double exposure_us);

  // The gantry (options.gantry) and the line profiler it carries (options.profiler).
  // Moves the axes (x, y, z mm, c deg, machine frame) and waits until in position (the clock
  // advances). Errors: failed_precondition (no gantry), out_of_range (outside the travel).
  Status MoveGantry(const std::array<double, 4>& xyzc);
  // What the gantry's encoders read: the position last commanded.
  std::array<double, 4> gantry_position() const;
  struct ProfileShot {
    std::vector<float> z_mm;  // sensor frame; NaN: invalid
    int64_t encoder = 0;      // the Y axis' encoder, latched with the exposure
    uint64_t sequence = 0;
    double t_s = 0.0;
  };
  // Exposes the profiler once where the gantry stands (the clock advances).
  // Errors: failed_precondition (no profiler).
  Result<ProfileShot> GrabProfile();
  Status SetProfilerExposure(double exposure_us);

  const WorldOptions& options() const { return options_; }

  // Truth, for tests only.
  const FrameTruth& last_truth() const { return truth_; }
  const CameraModel& true_camera() const;  // full-resolution true camera
  const Scene& scene() const;
  const ScanOptics& true_optics() const;
  // Clock ticks with the marking laser on (0 unless a marking list ran).
  int64_t laser_on_ticks() const { return laser_on_ticks_; }
  // Every marking pulse so far.
  const std::vector<MarkPulse>& mark_pulses() const { return pulses_; }
  const ListAbortTruth& last_list_abort() const { return last_abort_; }
  // Where the profiler's frame really is (the gantry's true position and the true mounting).
  Eigen::Isometry3d TrueSensorInWorld() const;
  // The surface the profiler sees at a world xy: the part's (or plate's) top less what the
  // marking laser ablated there, world z (mm).
  double TrueSurfaceZ(double x_mm, double y_mm) const;
  // Depth ablated at a world xy (mm).
  double AblatedDepthMm(double x_mm, double y_mm) const;

 private:
  struct PointerProgram {
    Eigen::Vector3d from, to;
    double speed_mm_per_s = 0.0;
    double start_s = 0.0;
  };
  struct BeamSample {
    MirrorAngles angles;
    double focus_z_mm = 0.0;
    double dt_s = 0.0;
  };
  void PointerSamples(double t0, double t1, std::vector<BeamSample>* samples) const;
  // Reflectance of the marked surface relative to the bare one at a world xy, averaged over a
  // square of half-size `half_mm` (a camera pixel's footprint); 1 where nothing was marked.
  // `on_part`: the part's material, else the stage plate's.
  double MarkFactor(double x_mm, double y_mm, double half_mm, bool on_part) const;
  Eigen::Vector3d PointerCommandAt(double t) const;
  // With options.real_time_factor > 0, sleeps until the wall clock has caught up with virtual
  // time `t` (scaled). A stretch where the simulation ran slower than that re-anchors instead
  // of letting virtual time race ahead afterwards.
  void PaceTo(double t);
  // A frame exposed from `t0` for the exposure (the clock does not move), cropped to the
  // region; `*link_s` the time it takes on the link.
  Result<Frame> Expose(double t0, double* link_s);
  double LinkSeconds(size_t bytes) const;

  // The devices' threads (a served GigE camera, a board emulator) and the job's thread may
  // reach the world at once: every public operation that changes it takes this lock.
  mutable std::recursive_mutex mutex_;
  WorldOptions options_;
  std::unique_ptr<Scene> scene_;
  std::unique_ptr<ScanOptics> true_optics_;
  std::unique_ptr<ScanOptics> design_optics_;
  std::function<Eigen::Vector2d(const Eigen::Vector2d&)> board_correction_;
  const void* board_correction_owner_ = nullptr;
  std::unique_ptr<CameraModel> camera_full_;
  double now_s_ = 0.0;
  std::optional<PointerProgram> pointer_;
  MirrorAngles rest_angles_;
  double exposure_us_;
  double stage_commanded_z_;  // what the stage reports (stage.scale_error_ppm)
  double gain_db_;
  int binning_ = 1;
  int region_first_row_ = 0, region_rows_ = 0;  // full-sensor rows; 0 rows: the whole sensor
  // The hardware-triggered camera: frames exposed on pulses, waiting with their arrival.
  struct Triggered {
    Result<Frame> frame;
    double arrival_s = 0.0;
  };
  bool trigger_armed_ = false;
  bool head_running_ = false;
  bool head_started_ = false;  // since the trigger was armed
  std::deque<Triggered> triggered_;
  double exposing_until_s_ = 0.0;
  double link_free_s_ = 0.0;
  int ignored_pulses_ = 0;
  std::condition_variable_any triggered_wake_;
  uint64_t frame_counter_ = 0;
  int64_t laser_on_ticks_ = 0;
  std::vector<MarkPulse> pulses_;
  ListAbortTruth last_abort_;
  bool paced_ = false;
  std::chrono::steady_clock::time_point pace_wall0_;
  double pace_virtual0_ = 0.0;
  std::unique_ptr<MarkMap> marks_;  // what the pulses ablated, for the cameras
  std::unique_ptr<fit::ModelExtension> field_effects_;  // carried by the head (may be empty)
  Eigen::Vector3d last_command_ = Eigen::Vector3d::Zero();
  // The mirrors' settling error since the last jump (repeatability), optical angles.
  MirrorAngles settle_error_;
  std::mt19937_64 head_rng_;
  void NewSettleError();
  std::unique_ptr<MarkMap> NewMarkMap() const;
  // The gantry: where it was commanded and where it really is (its repeatability).
  std::array<double, 4> gantry_command_{0.0, 0.0, 0.0, 0.0};
  std::array<double, 4> gantry_true_{0.0, 0.0, 0.0, 0.0};
  double profiler_exposure_us_ = 0.0;
  double block_cos_ = 1.0, block_sin_ = 0.0;  // the calibration block's rotation
  uint64_t profile_counter_ = 0;
  std::mt19937_64 profiler_rng_;
  // TrueSurfaceZ without the lock (the profile's hot loop holds it already).
  double SurfaceZ(double x_mm, double y_mm) const;
  // Whether the segment from `from` (on the surface) to `to` passes under the surface.
  bool SurfaceBlocks(const Eigen::Vector3d& from, const Eigen::Vector3d& to) const;
  FrameTruth truth_;
  // Ambient image (electrons per second per pixel), cached per stage height and binning.
  std::vector<float> ambient_e_per_s_;
  // Interreflection (light.interreflection): the surface seen by every glow_step_-th pixel of
  // each axis, and its electrons per second per W/m^2 of the pointer's light falling on it.
  struct GlowPoint {
    Eigen::Vector3f point, normal;
    float e_per_s_per_w_m2 = 0.0f;
  };
  std::vector<GlowPoint> glow_grid_;
  static constexpr int kGlowStep = 4;
  bool ambient_valid_ = false;
  double ambient_stage_z_ = 0.0;
  int ambient_binning_ = 0;
  std::unique_ptr<CameraModel> camera_binned_;
};

}  // namespace insitu::sim
