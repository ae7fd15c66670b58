#include "insitu/sim/scan_optics.h"

#include <cmath>

#include <Eigen/Dense>

namespace insitu::sim {
namespace {
// Field angle at which pupil_aberration is quoted: about the edge of a 255 mm lens's field.
constexpr double kPupilReferenceAngleRad = 0.2;
}  // namespace

ChiefRay ScanOptics::Trace(const MirrorAngles& angles) const {
  const double a = angles.x_rad;
  const double b = angles.y_rad;
  const Eigen::Vector3d d(std::sin(a), std::cos(a) * std::sin(b), -std::cos(a) * std::cos(b));
  const double sin_theta = std::hypot(d.x(), d.y());
  const double theta = std::atan2(sin_theta, -d.z());
  // r = f * theta along the azimuth of d; theta / sin(theta) -> 1 on the axis.
  const double scale = sin_theta > 1e-12 ? g_.focal_length_mm * theta / sin_theta
                                         : g_.focal_length_mm;
  ChiefRay ray;
  ray.focal_point_in_world = Eigen::Vector3d(scale * d.x(), scale * d.y(), 0.0);
  if (g_.telecentric) {
    ray.up = Eigen::Vector3d::UnitZ();
    return ray;
  }
  const double rel = theta / kPupilReferenceAngleRad;
  const double pupil_height = g_.exit_pupil_height_mm / (1.0 + g_.pupil_aberration * rel * rel);
  // The X deflection displaces the beam at the Y mirror by e*tan(a); the objective images the
  // entrance pupil into the exit pupil with magnification ~ L / f (paraxial).
  const double pupil_shift_x =
      g_.mirror_separation_mm * std::tan(a) * g_.exit_pupil_height_mm / g_.focal_length_mm;
  const Eigen::Vector3d pupil(pupil_shift_x, 0.0, pupil_height);
  ray.up = (pupil - ray.focal_point_in_world).normalized();
  return ray;
}

bool ScanOptics::Solve(double x_mm, double y_mm, double z_mm, MirrorAngles* angles) const {
  MirrorAngles a{x_mm / g_.focal_length_mm, y_mm / g_.focal_length_mm};
  const Eigen::Vector2d target(x_mm, y_mm);
  constexpr double kStep = 1e-7;
  for (int iter = 0; iter < 30; ++iter) {
    const Eigen::Vector2d p = Trace(a).AtHeight(z_mm).head<2>();
    const Eigen::Vector2d r = p - target;
    if (r.norm() < 1e-9) {
      *angles = a;
      return true;
    }
    const Eigen::Vector2d px = Trace({a.x_rad + kStep, a.y_rad}).AtHeight(z_mm).head<2>();
    const Eigen::Vector2d py = Trace({a.x_rad, a.y_rad + kStep}).AtHeight(z_mm).head<2>();
    Eigen::Matrix2d j;
    j.col(0) = (px - p) / kStep;
    j.col(1) = (py - p) / kStep;
    const Eigen::Vector2d delta = j.fullPivLu().solve(r);
    if (!delta.allFinite()) return false;
    a.x_rad -= delta.x();
    a.y_rad -= delta.y();
    if (std::abs(a.x_rad) > 1.0 || std::abs(a.y_rad) > 1.0) return false;
  }
  return false;
}

}  // namespace insitu::sim
