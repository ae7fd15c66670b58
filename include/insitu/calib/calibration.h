// The calibration set the reconstruction works from: camera intrinsics, the camera's pose in
// the galvo (= world) frame, the scan head's light-plane geometry, and (once measured) the
// height lookup. Files are versioned YAML in calib/ (format in calib/README.md).
//
// Frames: galvo frame as in sim/world_options.h (x, y galvo axes, z up, origin on the focal
// plane at the field centre); camera frame x right, y down, z forward; pixels as in OpenCV.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/calib/height_lookup.h"
#include "insitu/core/status.h"
#include "insitu/optics/grid_table.h"
#include "insitu/optics/scan_head.h"

namespace insitu::calib {

struct CameraIntrinsics {
  std::string model;   // camera model the numbers belong to
  std::string serial;  // camera serial, empty = any unit of the model (as-designed numbers)
  std::string lens;
  int width_px = 0;    // full sensor
  int height_px = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;  // Brown-Conrady, OpenCV convention

  Status Validate() const;
  // The same camera read out with `binning` x `binning` pixels averaged:
  // u_b = (u + 0.5) / b - 0.5.
  CameraIntrinsics Binned(int binning) const;
  // Normalised, undistorted image coordinates (x/z, y/z) of pixels (OpenCV undistortPoints).
  std::vector<Eigen::Vector2d> Undistort(const std::vector<Eigen::Vector2d>& pixels) const;
  // Pixel of a point in the camera frame (z > 0).
  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_camera) const;
};

enum class ScanLens { kFTheta, kTelecentric };

struct GalvoGeometry {
  ScanLens lens = ScanLens::kFTheta;
  // Height H of the seed's point a (0, 0, H): where the scan head's light planes meet.
  double pivot_height_mm = 355.0;
  Eigen::Isometry3d camera_from_galvo = Eigen::Isometry3d::Identity();

  Status Validate() const;
};

// The scan head as the machine knows it: the design geometry its controller's correction
// inverts, and (once a field calibration has run) the head as measured: the as-built geometry
// and zero errors fitted to marks the camera measured, the pointer's path against the marking
// beam, and a table of what the physical model leaves. Until measured, built = design: every
// command is taken to land where it asks. Galvo frame, mm.
struct HeadCalibration {
  bool measured = false;
  std::string measured_by;  // the field calibration that measured it
  optics::HeadModel model;  // design, built, zero offsets
  optics::BeamPath pointer;
  optics::GridTable residual_mm;  // marking beam: measured - model at the grid nodes

  Status Validate() const;
  // Where the marking beam lands for a command (x, y, focus z): on the plane z = cmd.z.
  // False outside the head's range.
  bool MarkSpot(const Eigen::Vector3d& cmd, Eigen::Vector3d* spot) const;
  // The chief ray of the pointer for a command.
  bool PointerRay(const Eigen::Vector3d& cmd, optics::ChiefRay* ray) const;
  // The command that puts the marking beam on target (x, y at height target.z): the field
  // correction of every list. Identity when not measured. False if it does not converge.
  bool MarkCommandFor(const Eigen::Vector3d& target, Eigen::Vector3d* cmd) const;
};

struct CalibrationSet {
  static constexpr int kFormatVersion = 1;
  int version = kFormatVersion;
  std::string produced_by;  // "as_designed" or the job that measured it
  std::string created;      // ISO 8601
  CameraIntrinsics camera;
  GalvoGeometry galvo;
  HeightLookup height_lookup;  // empty until a height calibration has run (method 2 needs it)
  HeadCalibration head;        // the design head until a field calibration has measured it

  Status Validate() const;
};

// Reads a calibration file. Errors name the file, the line and the key (not_found,
// parse_error, invalid_argument); a file of another format version is refused.
Result<CalibrationSet> LoadCalibration(const std::string& path);
// Writes atomically (temporary file + rename), so a failure never leaves a half file.
Status SaveCalibration(const CalibrationSet& set, const std::string& path);

// Refuses a calibration made for another camera: model, serial (when the file names one) and
// sensor size must match what the machine reports.
Status CheckCameraMatches(const CameraIntrinsics& calibration, const std::string& model,
                          const std::string& serial, int sensor_width_px,
                          int sensor_height_px);

}  // namespace insitu::calib
