// Line-structured-light triangulation with a galvo-defined light plane (seed 000 sec. 2.1,
// method 1). The light plane of one scan line passes through the galvo points a, b, c:
// b and c the commanded ends of the line on the focal plane (z = 0), a = (0, 0, H) for an
// f-theta objective, a = (x_b, 0, H) for a telecentric one (plane vertical). Transformed into
// the camera frame it gives A x + B y + C z + D = 0 (eq. 2); with the pinhole model (eq. 1)
// the stripe pixel's ray meets it (eq. 3), and the point goes back to the galvo frame (eq. 4).
// Frames: galvo (= world) and camera, as in calib/calibration.h; mm.
#pragma once

#include <optional>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/calib/calibration.h"

namespace insitu::geometry {

// Plane (A, B, C, D), unit normal (A, B, C), in the camera frame.
struct PlaneInCamera {
  Eigen::Vector4d coeffs = Eigen::Vector4d::Zero();
};

// The light plane through a, b, c (galvo frame) expressed in the camera frame (eq. 2).
PlaneInCamera LightPlaneInCamera(const Eigen::Vector3d& a_in_galvo,
                                 const Eigen::Vector3d& b_in_galvo,
                                 const Eigen::Vector3d& c_in_galvo,
                                 const Eigen::Isometry3d& camera_from_galvo);

// The light plane of a line on a head whose field has been measured: the least-squares plane
// through the pointer's chief rays along the line (calibration's head), each sampled over the
// scan's height range, expressed in the camera frame. The beams of one line sweep a slightly
// curved sheet; over +-z_range_mm the plane follows it to a few micrometres. Falls back to the
// seed's plane through a, b, c when the head is not measured or a ray cannot be traced.
PlaneInCamera LineLightPlane(const calib::CalibrationSet& calibration,
                             const Eigen::Vector3d& from_cmd, const Eigen::Vector3d& to_cmd,
                             double z_range_mm, const Eigen::Isometry3d& camera_from_galvo);

// Point a of the seed's model for a scan line whose ends are b and c.
Eigen::Vector3d PivotPoint(const calib::GalvoGeometry& galvo, const Eigen::Vector3d& b_in_galvo);

// Intersection of the ray through normalised image point (x, y) (undistorted, z = 1) with the
// plane (eq. 3). Empty if the ray is parallel to the plane or the point lies behind the camera.
std::optional<Eigen::Vector3d> IntersectRayWithPlane(const Eigen::Vector2d& normalized,
                                                     const PlaneInCamera& plane);

}  // namespace insitu::geometry
