// Where a line profiler's points lie on the workpiece (seed 002, section 1: eq. 1-10).
//
// A profile point i lies in the sensor's frame (SCS) at ((i - N/2) delta, 0, d_i) (eq. 5). The
// sensor is mounted on the machine's tool (TCS) by a constant rigid transform, the mounting:
// three Euler angles (eq. 8: R = Rz(phi) Ry(theta) Rx(psi); theta nutation, psi precession, phi
// spin) and a translation (the sixth axis' offset plus the sensor's, L + Delta, which only
// their sum shows). The machine takes the tool to the workpiece (WCS) by its axes: translation
// P_t from the linear axes and rotation R_t(a, c) from the A and C axes (eq. 3-4), identity on
// a gantry without rotary axes:
//   WCS p = R_t (R_mount SCS p + t_mount) + P_t                         (eq. 1)
// The mounting is calibrated, never read from a drawing. Eq. 10 in the form seed 002 prints it
// takes points of a block known in the workpiece frame and the same points as the sensor sees
// them: CalibrateMount, the rigid alignment of the two point sets (Eigen::umeyama). A line
// profiler does not see known points, it sees profiles across surfaces; CalibrateMountFromBlock
// is eq. 10 as a real machine solves it: profiles of a block of planar faces (measured by a CMM
// in the workpiece frame), each profile point's distance to the face it lies on minimised over
// the six mounting parameters.
//
// Frames: a BlockFace lives in the workpiece frame (WCS), a BlockScan's points in the sensor's
// (SCS), a ToolPose takes the tool frame (TCS) to the workpiece's; lengths in mm, angles in rad.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::inspect {

struct SensorMount {
  double theta_rad = 0.0, psi_rad = 0.0, phi_rad = 0.0;      // eq. 8
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();  // L + Delta (eq. 10)

  Eigen::Matrix3d Rotation() const;
  static SensorMount FromRotation(const Eigen::Matrix3d& r, const Eigen::Vector3d& t);
};

// The tool's place: the linear axes' position (P_t) and the A and C axes' angles.
struct ToolPose {
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();
  double a_rad = 0.0, c_rad = 0.0;
  Eigen::Matrix3d Rotation() const;  // eq. 4: Rz(c) Rx(a)
};

// A profile point in the sensor frame (eq. 5): x along the line, 0, z the range.
inline Eigen::Vector3d SensorPoint(double x_mm, double z_mm) { return {x_mm, 0.0, z_mm}; }

// Eq. 1.
Eigen::Vector3d ToWorkpiece(const ToolPose& tool, const SensorMount& mount,
                            const Eigen::Vector3d& sensor_point);

// One calibration point: where the sensor saw it, where the tool was (rotary axes at zero), and
// where it is on the block in the workpiece frame.
struct MountObservation {
  Eigen::Vector3d sensor_mm;
  Eigen::Vector3d tool_position_mm;
  Eigen::Vector3d workpiece_mm;
};

// The six mounting parameters in the order of MountCalibration's per-parameter arrays.
inline constexpr std::array<const char*, 6> kMountParameterNames = {
    "theta_rad", "psi_rad", "phi_rad", "translation_mm.x", "translation_mm.y", "translation_mm.z"};

struct MountCalibration {
  SensorMount mount;
  double rms_mm = 0.0;  // residual: of the workpiece points, or of the points' distances to faces
  int points = 0;       // points used

  // CalibrateMountFromBlock only. Points used on each face, in the order of the block's faces.
  std::vector<int> points_per_face;
  // Per parameter, in the order of kMountParameterNames (rad for the angles, mm for the
  // translation): the standard error from the Jacobian at the solution and the residual's rms
  // (random noise only), and the error gain: a systematic error of rms e in the points'
  // distances to their faces (the CMM's faces, the machine's axes, the sensor's linearity) moves
  // a translation by at most gain e and an angle by at most gain e / lever_mm. Infinite for a
  // parameter the scans do not see.
  std::array<double, 6> standard_error{};
  std::array<double, 6> error_gain{};
  // The points' rms distance from the axes of theta, psi and phi (the sensor's y, x and z
  // through the points' centroid): how far an angle moves them per rad.
  std::array<double, 3> lever_mm{};
  int rounds = 0;  // face assignments made (each followed by a least-squares solve)
};
// The observations are taken with the rotary axes at zero (eq. 9). Errors: invalid_argument with
// fewer than 3 points or points on one line (the rotation about it would be free).
Result<MountCalibration> CalibrateMount(const std::vector<MountObservation>& observations);

// One planar face of a calibration block, in the workpiece frame, as a CMM reports it: the plane
// (its unit normal pointing out of the block, towards the sensor, and a point of it) and its
// outline, a convex polygon in the plane (vertices in order, either way round) that tells which
// face a point lies on.
struct BlockFace {
  std::string name;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> outline_mm;
};

struct CalibrationBlock {
  std::string name;
  std::vector<BlockFace> faces;
  // invalid_argument naming the face and the field: no faces, a face without a name or with a
  // name taken, a normal not of unit length, an outline of fewer than 3 vertices, not convex,
  // of no area, or with a vertex more than 0.1 mm off the face's plane.
  Status Validate() const;
};

// The default block: a truncated square pyramid standing on a square base plate, its sides
// facing +-x and +-y of the workpiece frame. Sized for a profiler of an 80 mm line (3200 points
// of 25 um): a profile across its middle sees the plate on both sides, two sides at 45 deg
// (600 points each) and the top (1200 points), and the 15 mm height fits a measuring range of
// +-20 mm.
struct PyramidBlockSize {
  double base_mm = 60.0;    // side of the pyramid's base
  double top_mm = 30.0;     // side of its top
  double height_mm = 15.0;  // (60 - 30) / 2 = 15: sides at 45 deg
  double plate_mm = 80.0;   // side of the base plate
  Status Validate() const;  // 0 < top_mm < base_mm < plate_mm, height_mm > 0
};
// Faces "top", "side +x", "side -x", "side +y", "side -y" and "plate"; `base_centre_mm` is the
// centre of the pyramid's base on the plate's surface. Errors: invalid_argument from Validate().
Result<CalibrationBlock> PyramidBlock(const Eigen::Vector3d& base_centre_mm,
                                      const PyramidBlockSize& size = {});

// A block from a CMM report in YAML, in the workpiece frame and mm:
//   name: pyramid 60/30/15          # optional
//   faces:
//     - name: top
//       normal: [0, 0, 1]           # out of the block; normalised if within 1 % of unit length
//       point_mm: [200, 150, 35]
//       outline_mm: [[185, 135, 35], [215, 135, 35], [215, 165, 35], [185, 165, 35]]
// Errors name the file, line, field and face ("block.yaml:7: faces[1].normal: ... (face 'top')"):
// not_found (no file), parse_error (bad YAML), invalid_argument (a field missing, unknown, not a
// number or of the wrong count, or a face Validate() refuses).
Result<CalibrationBlock> LoadCalibrationBlock(const std::string& path);
// The same from text; `origin` names it in messages.
Result<CalibrationBlock> ParseCalibrationBlock(const std::string& text, const std::string& origin);

// One profile of the block: where the tool was and the profile's points in the sensor frame
// (eq. 5: x along the line, y = 0, z the range). Points that are not numbers are left out.
struct BlockScan {
  ToolPose tool;
  std::vector<Eigen::Vector3d> sensor_points;
};

struct BlockCalibrationOptions {
  // A point is assigned to the nearest face whose outline, shrunk by edge_margin_mm, contains
  // its projection, if it lies within the gate of that face; other points (edges, spikes, the
  // table around the block) are left out. The first gate covers how far the builder's drawing
  // may put a point off its face: a few mm, plus a few degrees over half the line. After each
  // solve it shrinks towards gate_sigmas robust standard deviations of the residuals, at most
  // halving, never below min_gate_mm, and never grows.
  double initial_gate_mm = 8.0;
  double gate_sigmas = 5.0;
  double min_gate_mm = 0.005;
  // Edges are rounded or chamfered and mix two faces in one reading: points projecting within
  // this of an outline's edge are left out.
  double edge_margin_mm = 0.5;
  int max_rounds = 50;       // face assignments before giving up
  int max_iterations = 100;  // Levenberg-Marquardt iterations per assignment
  // A parameter whose error gain (MountCalibration::error_gain) exceeds this is undetermined:
  // a few um of the block's or the machine's error would move it by more than 20 times that.
  double max_error_gain = 20.0;
  Status Validate() const;
};

// Eq. 10 over profiles of a block: the mount minimising the sum of squared distances of the
// profile points (taken to the workpiece by eq. 1 with each scan's tool pose, rotary axes
// anywhere) to their faces, by Levenberg-Marquardt from `initial` (the builder's drawing); the
// faces reassigned under each new estimate until the assignment settles.
// Errors: invalid_argument (options, block); failed_precondition when fewer than 6 points lie
// on faces, when the assignment does not settle in max_rounds, or when the scans leave
// parameters undetermined (only one face seen, all profiles across faces whose normals share a
// plane): the message names them, e.g. "translation_mm.y (not seen)", and the faces the points
// were found on. A start far off (tested: 30 mm, 15 deg) puts the points on the wrong faces and
// ends in one of these, or in the truth.
Result<MountCalibration> CalibrateMountFromBlock(const std::vector<BlockScan>& scans,
                                                 const CalibrationBlock& block,
                                                 const SensorMount& initial,
                                                 const BlockCalibrationOptions& options = {});

}  // namespace insitu::inspect
