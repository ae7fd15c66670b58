#include "insitu/geometry/triangulation.h"

#include <cmath>
#include <vector>

#include <Eigen/Eigenvalues>

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

PlaneInCamera LineLightPlane(const calib::CalibrationSet& calibration, const Eigen::Vector3d& from,
                             const Eigen::Vector3d& to, double z_range_mm,
                             const Eigen::Isometry3d& camera_from_galvo) {
  const Eigen::Vector3d b(from.x(), from.y(), 0.0), c(to.x(), to.y(), 0.0);
  const auto seed_plane = [&] {
    return LightPlaneInCamera(PivotPoint(calibration.galvo, b), b, c, camera_from_galvo);
  };
  if (!calibration.head.measured) return seed_plane();
  constexpr int kAlong = 7;
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < kAlong; ++i) {
    const Eigen::Vector3d cmd = from + (to - from) * (static_cast<double>(i) / (kAlong - 1));
    optics::ChiefRay ray;
    if (!calibration.head.PointerRay(cmd, &ray)) return seed_plane();
    for (double z : {-z_range_mm, 0.0, z_range_mm}) pts.push_back(camera_from_galvo * ray.AtHeight(z));
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : pts) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const Eigen::Vector3d n = eig.eigenvectors().col(0);  // smallest spread: the normal
  PlaneInCamera plane;
  plane.coeffs << n, -n.dot(mean);
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
