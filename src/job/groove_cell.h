// The line profiler's side of the groove cell (seed 002 section 1): its mounting (the machine
// builder's drawing, a calibrated mount file, or a calibration from the block), where a profile
// point lies in the machine frame, the panel's datum edges measured by the profiler, and the
// workpiece frame they define. Internal to the job module.
#pragma once

#include <array>
#include <atomic>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/config.h"
#include "insitu/core/status.h"
#include "insitu/hw/axis.h"
#include "insitu/hw/profiler.h"
#include "insitu/inspect/kinematics.h"

namespace insitu::job {

// [x, y, z, rx, ry, rz] (mm, deg; rotations about x, then y, then z: eq. 8's psi, theta, phi)
// as a mount, and back.
inspect::SensorMount MountFromPose(const std::array<double, 6>& pose);
std::array<double, 6> PoseFromMount(const inspect::SensorMount& mount);

// The mount file a profiler calibration writes and inspections read. Errors name the file and
// the key.
Status SaveMount(const inspect::MountCalibration& calibration, const hw::ProfilerInfo& profiler,
                 const std::string& path);
Result<inspect::SensorMount> LoadMount(const std::string& path);

// The tool's pose from the axes' position (rotary axes in degrees).
inspect::ToolPose ToolFromAxes(const hw::AxisPose& axes);
// Where the axes must stand for the sensor's frame origin to sit at `target` (machine frame)
// with its line (the sensor's x) along `line_xy` in the machine's xy plane: C turns the line,
// within (-90, 90] deg (a line crosses a groove either way round).
hw::AxisPose AxesForSensorAt(const inspect::SensorMount& mount, const Eigen::Vector3d& target,
                             const Eigen::Vector2d& line_xy);
// A profile point (x along the line, z the range) in the machine frame.
Eigen::Vector3d ProfilePointInMachine(const hw::AxisPose& axes, const inspect::SensorMount& mount,
                                      double x_mm, double z_mm);
// The sensor-frame x where a machine point projects onto the line.
double SensorXOf(const hw::AxisPose& axes, const inspect::SensorMount& mount,
                 const Eigen::Vector3d& machine_point);

// The panel's place on the machine as its tooling holes give it (the datums a chemical-milling
// template is pinned to): origin at hole A's centre, x toward hole B's, y square to it (both in
// the machine's xy plane).
struct PanelFrame {
  Eigen::Vector2d origin_mm = Eigen::Vector2d::Zero();
  Eigen::Vector2d x_axis = Eigen::Vector2d::UnitX(), y_axis = Eigen::Vector2d::UnitY();
  double top_z_mm = 0.0;  // the panel's top about its holes, machine z

  Eigen::Vector2d ToWorkpiece(const Eigen::Vector2d& machine_xy) const;
  Eigen::Vector2d ToMachine(const Eigen::Vector2d& workpiece_xy) const;
  double rotation_deg() const;
  // The frame that best fits the two holes as measured (a, b) to where the panel's drawing puts
  // them, (0, 0) and (distance, 0): the rigid least-squares fit of the pair, anchored at their
  // midpoint (each hole's measuring error counts half; on hole A alone it would count whole),
  // x along a to b.
  static PanelFrame FromHoles(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                              double distance_mm, double top_z);
};

// Where the machine builder's fixture puts the panel's tooling holes (nominal, machine xy),
// and how the profiler measures them.
struct DatumSpec {
  Eigen::Vector2d hole_a_mm{-50.0, -40.0}, hole_b_mm{50.0, -40.0};
  double hole_diameter_mm = 6.0;
  double top_z_mm = 2.31;  // the panel's top, machine z
  int profiles_per_hole = 7;
  Status Validate() const;
};

struct DatumResult {
  PanelFrame frame;
  Eigen::Vector2d hole_mm[2];       // measured centres, machine xy
  double hole_diameter_mm[2] = {0, 0};
  int rim_points = 0;
  double rim_rms_mm = 0.0;          // rim points off their fitted circles, rms
};

// A circle through points (Kasa's algebraic fit, then Gauss-Newton on the distances): centre,
// radius, rms. Errors: failed_precondition with fewer than 3 points or points on a line.
struct Circle2 {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double radius = 0.0, rms = 0.0;
};
Result<Circle2> FitCircle2(const std::vector<Eigen::Vector2d>& points);

// Measures the panel's tooling holes: profiles across each hole about its nominal place, the
// rims where the panel's top ends either side, a circle through them. Errors: device_error (a
// move or a profile failed), failed_precondition (a hole not seen: naming it and why).
Result<DatumResult> MeasureDatums(hw::Axis& axis, hw::Profiler& profiler,
                                  const inspect::SensorMount& mount, const DatumSpec& spec,
                                  const std::atomic<bool>* cancel);

// The block calibration: profiles across the block in two directions (the sensor's line along
// the machine's x, then along its y), from where the block is said to be, then eq. 10.
struct BlockScanSpec {
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();  // the block's plate top at its axis
  double extent_mm = 70.0;   // profiles over +-extent/2 about the centre
  int profiles_per_direction = 9;
  Status Validate() const;
};
Result<inspect::MountCalibration> CalibrateMountOnBlock(hw::Axis& axis, hw::Profiler& profiler,
                                                        const inspect::CalibrationBlock& block,
                                                        const inspect::SensorMount& drawing,
                                                        const BlockScanSpec& spec,
                                                        const std::atomic<bool>* cancel);

// The profiler: section of a job: the drawing's mount, a calibrated mount file, and the block.
struct ProfilerSpec {
  std::array<double, 6> drawing{0.0, -40.0, -140.0, 0.0, 0.0, 0.0};
  std::string mount_file;  // resolved; empty: calibrate on the block
  std::string block_file;  // a CMM report (resolved); empty: the pyramid block below
  inspect::PyramidBlockSize pyramid;
  BlockScanSpec block_scan;
  DatumSpec datums;
};
void ReadProfilerSection(ConfigReader& r, const std::string& folder, ProfilerSpec* spec);

// The block the spec names: its CMM report, or the pyramid at block_scan.centre_mm.
Result<inspect::CalibrationBlock> BlockOf(const ProfilerSpec& spec);

}  // namespace insitu::job
