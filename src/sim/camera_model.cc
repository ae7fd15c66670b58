#include "insitu/sim/camera_model.h"

#include <cmath>

namespace insitu::sim {

CameraModel::CameraModel(const CameraOptions& options) : o_(options) {
  fx_ = fy_ = o_.lens_focal_length_mm / (o_.pixel_pitch_um * 1e-3);
  cx_ = 0.5 * (o_.width_px - 1) + o_.principal_point_offset_px[0];
  cy_ = 0.5 * (o_.height_px - 1) + o_.principal_point_offset_px[1];
  center_in_world_ = Eigen::Vector3d(o_.position_mm[0], o_.position_mm[1], o_.position_mm[2]);
  const Eigen::Vector3d target(o_.look_at_mm[0], o_.look_at_mm[1], o_.look_at_mm[2]);
  const Eigen::Vector3d z = (target - center_in_world_).normalized();
  // Image 'down' (camera y) points away from world up as far as the view direction allows.
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-9) x = Eigen::Vector3d::UnitX();
  x.normalize();
  Eigen::Vector3d y = z.cross(x);
  const double roll = o_.roll_deg * M_PI / 180.0;
  const Eigen::Vector3d xr = std::cos(roll) * x + std::sin(roll) * y;
  const Eigen::Vector3d yr = -std::sin(roll) * x + std::cos(roll) * y;
  Eigen::Matrix3d world_from_camera_rot;
  world_from_camera_rot.col(0) = xr;
  world_from_camera_rot.col(1) = yr;
  world_from_camera_rot.col(2) = z;
  Eigen::Isometry3d world_from_camera = Eigen::Isometry3d::Identity();
  world_from_camera.linear() = world_from_camera_rot;
  world_from_camera.translation() = center_in_world_;
  camera_from_world_ = world_from_camera.inverse();
}

Eigen::Vector2d CameraModel::Distort(const Eigen::Vector2d& n) const {
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (o_.k1 + r2 * (o_.k2 + r2 * o_.k3));
  const double xd = x * radial + 2.0 * o_.p1 * x * y + o_.p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + o_.p1 * (r2 + 2.0 * y * y) + 2.0 * o_.p2 * x * y;
  return {xd, yd};
}

bool CameraModel::Project(const Eigen::Vector3d& point_in_world, Eigen::Vector2d* pixel) const {
  const Eigen::Vector3d pc = camera_from_world_ * point_in_world;
  if (pc.z() <= 1e-6) return false;
  const Eigen::Vector2d d = Distort(pc.head<2>() / pc.z());
  *pixel = Eigen::Vector2d(fx_ * d.x() + cx_, fy_ * d.y() + cy_);
  return true;
}

Eigen::Matrix<double, 2, 3> CameraModel::ProjectJacobian(const Eigen::Vector3d& p) const {
  Eigen::Matrix<double, 2, 3> j;
  constexpr double h = 1e-4;  // mm; the projection is smooth on this scale
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d dp = Eigen::Vector3d::Zero();
    dp[k] = h;
    Eigen::Vector2d a, b;
    Project(p + dp, &a);
    Project(p - dp, &b);
    j.col(k) = (a - b) / (2.0 * h);
  }
  return j;
}

Eigen::Vector3d CameraModel::PixelRayInWorld(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d d((pixel.x() - cx_) / fx_, (pixel.y() - cy_) / fy_);
  Eigen::Vector2d n = d;
  for (int i = 0; i < 30; ++i) {  // fixed point; converges for the mild lenses of machine vision
    const Eigen::Vector2d step = d - Distort(n);
    n += step;
    if (step.squaredNorm() < 1e-24) break;
  }
  const Eigen::Vector3d ray_in_camera = Eigen::Vector3d(n.x(), n.y(), 1.0).normalized();
  return camera_from_world_.linear().transpose() * ray_in_camera;
}

double CameraModel::Cos4(const Eigen::Vector2d& pixel) const {
  const double x = (pixel.x() - cx_) / fx_, y = (pixel.y() - cy_) / fy_;
  const double c2 = 1.0 / (1.0 + x * x + y * y);
  return c2 * c2;
}

}  // namespace insitu::sim
