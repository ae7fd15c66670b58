// Camera calibration on the machine: intrinsics from chessboard views (Zhang's method,
// cv::calibrateCamera) and the camera's pose in the galvo frame from pointer spots shot at
// known galvo positions (seed 000 sec. 3.3.1 step 1, Fig. 6a; cv::solvePnP).
// Frames as in calibration.h. Results come back as summaries with ok and a message: a
// calibration that fails leaves nothing half-made for the caller to save.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/calib/calibration.h"

namespace insitu::calib {

struct BoardGeometry {
  int inner_cols = 11;
  int inner_rows = 8;
  double square_mm = 10.0;
};

struct IntrinsicsOptions {
  int min_views = 8;              // boards found in at least this many frames
  double min_coverage = 0.35;     // fraction of the image (16 x 16 cells) holding corners
  double max_rms_px = 0.5;        // reprojection RMS above this fails the calibration
  bool fix_k3 = true;             // a 15 mm lens needs no 6th-order term; fitting it overfits

  Status Validate() const;
};

struct IntrinsicsSummary {
  bool ok = false;
  std::string message;
  int views = 0;
  double rms_px = 0.0;
  double coverage = 0.0;
  std::vector<double> view_rms_px;
  // One-sigma uncertainties OpenCV derives from the residuals (fx, fy, cx, cy, k1, k2, p1, p2).
  std::vector<double> stddev;
  CameraIntrinsics intrinsics;  // width/height/model/serial filled by the caller
};

// `corners[k]`: the inner corners of view k in board order (vision::FindChessboard).
IntrinsicsSummary CalibrateIntrinsics(const std::vector<std::vector<Eigen::Vector2d>>& corners,
                                      const BoardGeometry& board, int width_px, int height_px,
                                      const IntrinsicsOptions& options);

// One pointer spot: where the head was told to put it and where the camera saw it.
struct GalvoSpot {
  Eigen::Vector3d commanded_in_galvo;  // mm
  Eigen::Vector2d pixel;
};

struct AlignmentOptions {
  int min_spots = 6;
  double min_spread_mm = 10.0;   // the spots must span at least this in two directions
  double max_rms_mm = 0.2;

  Status Validate() const;
};

struct AlignmentSummary {
  bool ok = false;
  std::string message;
  int spots = 0;
  Eigen::Isometry3d camera_from_galvo = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;
  double rms_mm = 0.0;  // spot position error in the galvo frame, on the spot's own height
  double max_mm = 0.0;
};

AlignmentSummary AlignCameraToGalvo(const std::vector<GalvoSpot>& spots,
                                    const CameraIntrinsics& camera,
                                    const AlignmentOptions& options);

// The stage plate's plane as the camera sees it, from one view of the chessboard lying flat on
// the plate (metric: the board's squares, not the scan head, give the scale). Plate frame: x,
// y along the board's rows and columns (origin at its first inner corner), z = 0 the plate's
// top, `thickness_mm` under the board's printed face, +z toward the camera.
struct PlatePoseSummary {
  bool ok = false;
  std::string message;
  Eigen::Isometry3d camera_from_plate = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;  // corner reprojection
};
PlatePoseSummary PlateFromBoard(const std::vector<Eigen::Vector2d>& corners,
                                const BoardGeometry& board, const CameraIntrinsics& camera,
                                double thickness_mm);

// Where the rays of `pixels` (full-sensor pixels of `camera`) meet the plane z = 0 of a frame
// the camera sees at `camera_from_plane`: (x, y) in that frame, mm. Empty for a ray parallel to
// the plane or meeting it behind the camera.
std::vector<std::optional<Eigen::Vector2d>> PixelsOnPlane(
    const std::vector<Eigen::Vector2d>& pixels, const CameraIntrinsics& camera,
    const Eigen::Isometry3d& camera_from_plane);

}  // namespace insitu::calib
