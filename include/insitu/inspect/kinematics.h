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
// The mounting is calibrated, never read from a drawing: with the rotary axes at zero, points
// of a calibration block known in the workpiece frame (measured by a CMM) and the same points
// as the sensor sees them give eq. 10's overdetermined system; its least-squares solution with
// R a rotation is the rigid alignment of the two point sets (Eigen::umeyama).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
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

struct MountCalibration {
  SensorMount mount;
  double rms_mm = 0.0;  // residual of the workpiece points
  int points = 0;
};
// The observations are taken with the rotary axes at zero (eq. 9). Errors: invalid_argument with
// fewer than 3 points or points on one line (the rotation about it would be free).
Result<MountCalibration> CalibrateMount(const std::vector<MountObservation>& observations);

}  // namespace insitu::inspect
