// The simulated machine: scan head, camera, Z stage and part, on one virtual clock.
//
// The hw sim backends (src/hw/sim) drive a SimWorld exactly as the real backends drive a
// scan head, a camera and a stage: commands in, frames out. Nothing here is visible to the
// reconstruction except through those interfaces; the truth accessors at the bottom exist
// for tests that measure the algorithms against reality.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include <Eigen/Core>

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
  // Runs a list with the marking laser (laser on during marks), blocking in virtual time.
  Status ExecuteMarkingList(const std::vector<ListMove>& moves, double jump_speed_mm_per_s,
                            double mark_speed_mm_per_s);
  // Where the head would put the chief ray for a command (after its correction table).
  bool CommandToAngles(const Eigen::Vector3d& point_in_galvo, MirrorAngles* angles) const;

  // Z stage.
  Status MoveStage(double z_mm);
  double stage_z() const;

  // The operator puts the calibration board at pose `index` of board.poses (modulo their
  // number). Errors: failed_precondition if the world has no board.
  Status PlaceBoard(int index);
  void RemoveBoard();
  // The operator takes the part off the stage.
  void RemovePart();
  int board_pose_count() const;

  // Camera.
  Status SetExposure(double exposure_us);
  Status SetGain(double gain_db);
  Status SetBinning(int binning);
  int binning() const;
  double exposure_us() const;
  // Exposes from now for the exposure time (the clock advances) and returns the frame.
  Result<Frame> Grab();

  const WorldOptions& options() const { return options_; }

  // Truth, for tests only.
  const FrameTruth& last_truth() const { return truth_; }
  const CameraModel& true_camera() const;  // full-resolution true camera
  const Scene& scene() const;
  const ScanOptics& true_optics() const;
  // Number of marking pulses that fired (0 unless a marking list ran).
  int64_t laser_on_ticks() const { return laser_on_ticks_; }

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
  Eigen::Vector3d PointerCommandAt(double t) const;

  WorldOptions options_;
  std::unique_ptr<Scene> scene_;
  std::unique_ptr<ScanOptics> true_optics_;
  std::unique_ptr<ScanOptics> design_optics_;
  std::unique_ptr<CameraModel> camera_full_;
  double now_s_ = 0.0;
  std::optional<PointerProgram> pointer_;
  MirrorAngles rest_angles_;
  double exposure_us_;
  double gain_db_;
  int binning_ = 1;
  uint64_t frame_counter_ = 0;
  int64_t laser_on_ticks_ = 0;
  FrameTruth truth_;
  // Ambient image (electrons per second per pixel), cached per stage height and binning.
  std::vector<float> ambient_e_per_s_;
  bool ambient_valid_ = false;
  double ambient_stage_z_ = 0.0;
  int ambient_binning_ = 0;
  std::unique_ptr<CameraModel> camera_binned_;
};

}  // namespace insitu::sim
