// Ray optics of a two-mirror galvo scan head with an f-theta or telecentric objective.
//
// The input beam hits the X mirror, then (mirror_separation_mm further on) the Y mirror; both
// deflect by twice their mechanical angle. The direction leaving the Y mirror,
//   d = (sin a, cos a sin b, -cos a cos b)   (a, b: optical angles of the X and Y mirrors),
// enters the objective at field angle theta = acos(cos a cos b), azimuth phi. An f-theta
// objective images it at r = f * theta on the focal plane (z = 0); the chief ray leaves toward
// that point from the exit pupil, whose apparent height falls slowly with field angle (pupil
// aberration) and which is shifted sideways by the X deflection at the Y mirror. So the field
// pincushion (x) and barrel (y), and the fact that the beams of one 'scan line' sweep a
// slightly curved surface and not a plane, come out of the geometry.
// Frame: world = galvo frame (see world_options.h), mm.
#pragma once

#include <Eigen/Core>

#include "insitu/sim/world_options.h"

namespace insitu::sim {

// Optical deflection angles of the two mirrors (twice the mechanical angles), radians.
struct MirrorAngles {
  double x_rad = 0.0;
  double y_rad = 0.0;
};

struct ChiefRay {
  Eigen::Vector3d focal_point_in_world;  // where the chief ray crosses z = 0
  Eigen::Vector3d up;                    // unit vector along the ray, pointing up (to the head)

  // The point of the ray at height z_mm.
  Eigen::Vector3d AtHeight(double z_mm) const {
    return focal_point_in_world + up * (z_mm / up.z());
  }
};

class ScanOptics {
 public:
  explicit ScanOptics(const ScanOpticsGeometry& geometry) : g_(geometry) {}

  ChiefRay Trace(const MirrorAngles& angles) const;

  // The mirror angles whose chief ray passes through (x_mm, y_mm) at height z_mm (Newton
  // iteration from the paraxial guess). Returns false if it does not converge (far outside
  // the field).
  bool Solve(double x_mm, double y_mm, double z_mm, MirrorAngles* angles) const;

  const ScanOpticsGeometry& geometry() const { return g_; }

 private:
  ScanOpticsGeometry g_;
};

}  // namespace insitu::sim
