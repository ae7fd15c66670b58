// The true camera of the simulated world: pinhole + Brown-Conrady distortion (OpenCV's
// k1, k2, p1, p2, k3 convention) at a pose built from position, look-at point and roll.
// Camera frame: x right, y down, z forward (optical axis); pixel (u, v) as in OpenCV.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/sim/world_options.h"

namespace insitu::sim {

class CameraModel {
 public:
  explicit CameraModel(const CameraOptions& options);

  // Projects a world point; false if it lies behind the camera.
  bool Project(const Eigen::Vector3d& point_in_world, Eigen::Vector2d* pixel) const;
  // Jacobian of Project with respect to the world point (2 x 3), by central differences.
  Eigen::Matrix<double, 2, 3> ProjectJacobian(const Eigen::Vector3d& point_in_world) const;
  // Unit ray in the world through a pixel (inverts the distortion iteratively).
  Eigen::Vector3d PixelRayInWorld(const Eigen::Vector2d& pixel) const;

  const Eigen::Vector3d& center_in_world() const { return center_in_world_; }
  const Eigen::Isometry3d& camera_from_world() const { return camera_from_world_; }
  double fx() const { return fx_; }
  double fy() const { return fy_; }
  double cx() const { return cx_; }
  double cy() const { return cy_; }
  // cos^4 of the angle between the pixel's ray and the optical axis (vignetting law).
  double Cos4(const Eigen::Vector2d& pixel) const;

 private:
  Eigen::Vector2d Distort(const Eigen::Vector2d& normalized) const;

  CameraOptions o_;
  double fx_, fy_, cx_, cy_;
  Eigen::Isometry3d camera_from_world_;
  Eigen::Vector3d center_in_world_;
};

}  // namespace insitu::sim
