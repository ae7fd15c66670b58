#include "insitu/geometry/triangulation.h"

#include <cmath>

namespace insitu::geometry {

PlaneInCamera LightPlaneInCamera(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                 const Eigen::Vector3d& c,
                                 const Eigen::Isometry3d& camera_from_galvo) {
  const Eigen::Vector3d pa = camera_from_galvo * a;
  const Eigen::Vector3d pb = camera_from_galvo * b;
  const Eigen::Vector3d pc = camera_from_galvo * c;
  const Eigen::Vector3d n = (pb - pa).cross(pc - pa).normalized();
  PlaneInCamera plane;
  plane.coeffs << n, -n.dot(pa);  // seed 000 eq. (2)
  return plane;
}

Eigen::Vector3d PivotPoint(const calib::GalvoGeometry& galvo, const Eigen::Vector3d& b) {
  if (galvo.lens == calib::ScanLens::kTelecentric) {
    return {b.x(), 0.0, galvo.pivot_height_mm};
  }
  return {0.0, 0.0, galvo.pivot_height_mm};
}

std::optional<Eigen::Vector3d> IntersectRayWithPlane(const Eigen::Vector2d& xy,
                                                     const PlaneInCamera& plane) {
  // Seed 000 eq. (3) in normalised coordinates: (x_c, y_c, z_c) = z_c (x, y, 1) on the plane.
  const Eigen::Vector3d ray(xy.x(), xy.y(), 1.0);
  const double denom = plane.coeffs.head<3>().dot(ray);
  if (std::abs(denom) < 1e-12) return std::nullopt;
  const double z = -plane.coeffs[3] / denom;
  if (!(z > 0)) return std::nullopt;
  return Eigen::Vector3d(ray * z);
}

}  // namespace insitu::geometry
