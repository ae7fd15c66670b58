#include "insitu/optics/scan_head.h"

#include <cmath>

#include <Eigen/Dense>

#include "insitu/core/validate.h"
#include "insitu/optics/newton.h"

namespace insitu::optics {

Status HeadGeometry::Validate() const {
  if (!IsPositiveFinite(focal_length_mm))
    return InvalidValue("focal_length_mm", "> 0", focal_length_mm);
  if (!(mirror_separation_mm >= 0.0 && mirror_separation_mm < 200.0)) {
    return InvalidValue("mirror_separation_mm", "in [0, 200)", mirror_separation_mm);
  }
  if (!IsPositiveFinite(exit_pupil_height_mm)) {
    return InvalidValue("exit_pupil_height_mm", "> 0", exit_pupil_height_mm);
  }
  if (!(std::abs(pupil_aberration) < 1.0)) {
    return InvalidValue("pupil_aberration", "in (-1, 1)", pupil_aberration);
  }
  // |c3| theta^2 stays well under 1 over a 0.3 rad field: a lens, not a fisheye.
  if (!(std::abs(ftheta_c3) <= 2.0)) return InvalidValue("ftheta_c3", "in [-2, 2]", ftheta_c3);
  if (!(std::abs(ftheta_c5) <= 20.0)) return InvalidValue("ftheta_c5", "in [-20, 20]", ftheta_c5);
  if (!(std::abs(x_axis_tilt_mrad) <= 50.0)) {
    return InvalidValue("x_axis_tilt_mrad", "in [-50, 50]", x_axis_tilt_mrad);
  }
  if (!(std::abs(y_axis_tilt_mrad) <= 50.0)) {
    return InvalidValue("y_axis_tilt_mrad", "in [-50, 50]", y_axis_tilt_mrad);
  }
  return Status::Ok();
}

Status BeamPath::Validate() const {
  if (!(std::abs(offset_x_mrad) <= 50.0))
    return InvalidValue("offset_x_mrad", "in [-50, 50]", offset_x_mrad);
  if (!(std::abs(offset_y_mrad) <= 50.0))
    return InvalidValue("offset_y_mrad", "in [-50, 50]", offset_y_mrad);
  if (!(std::abs(lateral_colour_pct) <= 10.0)) {
    return InvalidValue("lateral_colour_pct", "in [-10, 10]", lateral_colour_pct);
  }
  return Status::Ok();
}

Status HeadModel::Validate() const {
  INSITU_RETURN_IF_ERROR(design.Validate().Prefixed("design"));
  INSITU_RETURN_IF_ERROR(built.Validate().Prefixed("built"));
  if (!(std::abs(x_zero_offset_mrad) <= 50.0)) {
    return InvalidValue("x_zero_offset_mrad", "in [-50, 50]", x_zero_offset_mrad);
  }
  if (!(std::abs(y_zero_offset_mrad) <= 50.0)) {
    return InvalidValue("y_zero_offset_mrad", "in [-50, 50]", y_zero_offset_mrad);
  }
  return Status::Ok();
}

HeadParamsT<double> ParamsOf(const HeadGeometry& g, const BeamPath& beam) {
  HeadParamsT<double> h;
  h.focal_length_mm = g.focal_length_mm;
  h.mirror_separation_mm = g.mirror_separation_mm;
  h.c3 = g.ftheta_c3;
  h.c5 = g.ftheta_c5;
  h.x_axis_tilt_rad = g.x_axis_tilt_mrad * 1e-3;
  h.y_axis_tilt_rad = g.y_axis_tilt_mrad * 1e-3;
  h.beam_offset_x_rad = beam.offset_x_mrad * 1e-3;
  h.beam_offset_y_rad = beam.offset_y_mrad * 1e-3;
  h.beam_focal_scale = 1.0 + beam.lateral_colour_pct * 1e-2;
  h.exit_pupil_height_mm = g.exit_pupil_height_mm;
  h.pupil_aberration = g.pupil_aberration;
  h.telecentric = g.telecentric;
  return h;
}

ChiefRay ScanOptics::Trace(const MirrorAngles& angles, const BeamPath& beam) const {
  double xy[2], up[3];
  TraceChiefRay(ParamsOf(g_, beam), angles.x_rad, angles.y_rad, xy, up);
  ChiefRay ray;
  ray.focal_point_in_world = Eigen::Vector3d(xy[0], xy[1], 0.0);
  ray.up = Eigen::Vector3d(up[0], up[1], up[2]);
  return ray;
}

bool ScanOptics::Solve(double x_mm, double y_mm, double z_mm, MirrorAngles* angles,
                       const BeamPath& beam) const {
  const HeadParamsT<double> h = ParamsOf(g_, beam);
  const auto map = [&](const Eigen::Vector2d& a) {
    double xy[2], up[3];
    TraceChiefRay(h, a.x(), a.y(), xy, up);
    return Eigen::Vector2d(xy[0] + up[0] * z_mm / up[2], xy[1] + up[1] * z_mm / up[2]);
  };
  Eigen::Vector2d a(x_mm / g_.focal_length_mm, y_mm / g_.focal_length_mm);
  if (!optics::InvertMap2d(map, Eigen::Vector2d(x_mm, y_mm), 1e-7, 1e-9, &a)) return false;
  if (std::abs(a.x()) > 1.0 || std::abs(a.y()) > 1.0) return false;
  *angles = {a.x(), a.y()};
  return true;
}

bool HeadModel::CommandAngles(const Eigen::Vector3d& command, MirrorAngles* angles) const {
  if (!ScanOptics(design).Solve(command.x(), command.y(), command.z(), angles)) return false;
  angles->x_rad += x_zero_offset_mrad * 1e-3;
  angles->y_rad += y_zero_offset_mrad * 1e-3;
  return true;
}

bool HeadModel::Land(const Eigen::Vector3d& command, const BeamPath& beam, ChiefRay* ray) const {
  MirrorAngles a;
  if (!CommandAngles(command, &a)) return false;
  *ray = ScanOptics(built).Trace(a, beam);
  return true;
}

bool HeadModel::Spot(const Eigen::Vector3d& command, const BeamPath& beam,
                     Eigen::Vector3d* spot) const {
  ChiefRay ray;
  if (!Land(command, beam, &ray)) return false;
  *spot = ray.AtHeight(command.z());
  return true;
}

bool HeadModel::CommandFor(const Eigen::Vector3d& target, const BeamPath& beam,
                           Eigen::Vector3d* command) const {
  const double z = target.z();
  const auto map = [&](const Eigen::Vector2d& c) {
    Eigen::Vector3d s;
    if (!Spot(Eigen::Vector3d(c.x(), c.y(), z), beam, &s)) return Eigen::Vector2d(NAN, NAN);
    return Eigen::Vector2d(s.x(), s.y());
  };
  Eigen::Vector2d c = target.head<2>();
  // Steps of 1e-4 mm: the design inversion inside the map converges to 1e-9 mm.
  if (!optics::InvertMap2d(map, target.head<2>(), 1e-4, 1e-7, &c)) return false;
  *command = Eigen::Vector3d(c.x(), c.y(), z);
  return true;
}

}  // namespace insitu::optics
