// Ray optics of a two-mirror galvo scan head with an f-theta (or telecentric) objective: the
// project's one physical model of the head, used by the simulator (its truth), by the field
// calibration (fitted to what the cameras measure) and by the calibration file (the measured
// head the scans and marks rely on).
//
// The input beam travels along +x and hits the X mirror (rotation axis z), which sends it along
// +y to the Y mirror (rotation axis x, `mirror_separation_mm` further on), which sends it down.
// Each mirror deflects by twice its mechanical angle; the optical angles are a (X) and b (Y).
// The mirrors are traced as real reflections, so with axes as designed the direction leaving
// the Y mirror is d = (sin a, cos a sin b, -cos a cos b), and a mirror whose rotation axis is
// tilted toward its incoming beam sweeps a cone instead of a plane (scan-line bow). d enters
// the objective at field angle theta = acos(-d_z), azimuth atan2(d_y, d_x). The f-theta
// objective images it at r = f theta (1 + c3 theta^2 + c5 theta^4) on the focal plane z = 0;
// the chief ray leaves toward that point from the exit pupil, whose apparent height falls with
// field angle (pupil aberration) and which the X deflection shifts sideways (the beam is
// displaced by e tan a at the Y mirror; the objective images the entrance pupil with
// magnification ~ L / f). So the field pincushion (x) and barrel (y), and the slightly curved
// sheet the beams of one scan line sweep, come out of the geometry.
//
// A beam other than the one the head was designed for (the red pointer beside the 1064 nm
// marking laser) may enter slightly misaligned and sees another focal length (lateral colour):
// BeamPath.
//
// Frame: galvo frame, mm: origin at the field centre on the focal plane, z up to the head.
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::optics {

// Geometry of a head, as built or as designed.
struct HeadGeometry {
  double focal_length_mm = 255.0;        // f-theta: r = f theta (1 + c3 theta^2 + c5 theta^4)
  double mirror_separation_mm = 16.0;    // X mirror to Y mirror along the beam
  double exit_pupil_height_mm = 310.0;   // chief rays leave as if from this height
  // Exit-pupil (chief-ray) aberration: the apparent source of chief rays moves down with
  // field angle, L(theta) = L / (1 + pupil_aberration * (theta / 0.2 rad)^2).
  double pupil_aberration = 0.03;
  bool telecentric = false;              // chief rays parallel to z
  // Departure of the objective from r = f theta (theta in rad): its f-theta distortion.
  double ftheta_c3 = 0.0;
  double ftheta_c5 = 0.0;
  // Tilt of each mirror's rotation axis toward its incoming beam, mrad (0: the axis is normal
  // to the plane the mirror was meant to scan in).
  double x_axis_tilt_mrad = 0.0;
  double y_axis_tilt_mrad = 0.0;

  Status Validate() const;
};

// Optical deflection angles of the two mirrors (twice the mechanical angles), radians.
struct MirrorAngles {
  double x_rad = 0.0;
  double y_rad = 0.0;
};

// How a beam other than the design beam goes through the head.
struct BeamPath {
  // Misalignment of the beam entering the head against the design beam, mrad: moves its spot
  // by about f * offset on the field (x, y).
  double offset_x_mrad = 0.0;
  double offset_y_mrad = 0.0;
  // Lateral colour: the objective's image height for this beam relative to the design beam's,
  // in percent (f_beam = f (1 + lateral_colour_pct / 100)).
  double lateral_colour_pct = 0.0;

  Status Validate() const;
};

struct ChiefRay {
  Eigen::Vector3d focal_point_in_world = Eigen::Vector3d::Zero();  // crossing of z = 0
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();  // unit vector along the ray, toward the head

  // The point of the ray at height z_mm.
  Eigen::Vector3d AtHeight(double z_mm) const {
    return focal_point_in_world + up * (z_mm / up.z());
  }
};

// The chief ray for mirror angles (a, b) of a head whose fitted numbers may be Ceres jets:
// f, e, c3, c5, the axis tilts (rad) and the beam's offsets (rad) and focal scale are T; the
// pupil's height, aberration and telecentricity are plain numbers (not fitted). Writes the
// focal point (x, y at z = 0) and the unit up vector.
template <typename T>
struct HeadParamsT {
  T focal_length_mm, mirror_separation_mm, c3, c5, x_axis_tilt_rad, y_axis_tilt_rad;
  T beam_offset_x_rad, beam_offset_y_rad, beam_focal_scale;
  double exit_pupil_height_mm = 310.0, pupil_aberration = 0.0;
  bool telecentric = false;
};

namespace internal {
// Rotation of v about the unit axis u by angle phi (Rodrigues).
template <typename T>
void Rotate(const T u[3], const T& phi, const T v[3], T out[3]) {
  using std::cos;
  using std::sin;
  const T c = cos(phi), s = sin(phi);
  const T dot = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
  const T cr[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  for (int i = 0; i < 3; ++i) out[i] = v[i] * c + cr[i] * s + u[i] * dot * (T(1) - c);
}
template <typename T>
void Reflect(const T v[3], const T n[3], T out[3]) {
  const T dot = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
  for (int i = 0; i < 3; ++i) out[i] = v[i] - T(2) * dot * n[i];
}
}  // namespace internal

template <typename T>
void TraceChiefRay(const HeadParamsT<T>& h, const T& a, const T& b, T focal_xy[2], T up[3]) {
  using std::atan2;
  using std::cos;
  using std::sin;
  using std::sqrt;
  using std::tan;
  const double k = 1.0 / std::sqrt(2.0);
  // The beam entering the head: +x, misaligned by the beam's offsets (signs so that +offset
  // moves the spot toward +x, +y).
  T in[3] = {T(1), h.beam_offset_x_rad, -h.beam_offset_y_rad};
  const T norm_in = sqrt(in[0] * in[0] + in[1] * in[1] + in[2] * in[2]);
  for (T& c : in) c /= norm_in;
  // X mirror: rest normal sends +x to +y; mechanical angle -a/2 about its axis gives d_x = sin a.
  const T ax[3] = {sin(h.x_axis_tilt_rad), T(0), cos(h.x_axis_tilt_rad)};
  const T nx0[3] = {T(-k), T(k), T(0)};
  T nx[3], after_x[3];
  internal::Rotate(ax, T(-0.5) * a, nx0, nx);
  internal::Reflect(in, nx, after_x);
  // Y mirror: rest normal sends +y to -z; mechanical angle b/2 gives d_y = cos a sin b.
  const T ay[3] = {cos(h.y_axis_tilt_rad), sin(h.y_axis_tilt_rad), T(0)};
  const T ny0[3] = {T(0), T(k), T(k)};
  T ny[3], d[3];
  internal::Rotate(ay, T(0.5) * b, ny0, ny);
  internal::Reflect(after_x, ny, d);

  const T sin2 = d[0] * d[0] + d[1] * d[1];
  const T f = h.focal_length_mm * h.beam_focal_scale;
  T theta, scale;
  if (sin2 < T(1e-24)) {  // on the axis: theta / sin(theta) -> 1
    theta = T(0);
    scale = f;
  } else {
    const T sin_theta = sqrt(sin2);
    theta = atan2(sin_theta, -d[2]);
    const T t2 = theta * theta;
    scale = f * theta * (T(1) + h.c3 * t2 + h.c5 * t2 * t2) / sin_theta;
  }
  focal_xy[0] = scale * d[0];
  focal_xy[1] = scale * d[1];
  if (h.telecentric) {
    up[0] = T(0);
    up[1] = T(0);
    up[2] = T(1);
    return;
  }
  const T rel = theta / T(0.2);  // the field angle at which pupil_aberration is quoted
  const T pupil_height = T(h.exit_pupil_height_mm) / (T(1) + T(h.pupil_aberration) * rel * rel);
  const T pupil_shift_x =
      h.mirror_separation_mm * tan(a) * T(h.exit_pupil_height_mm) / h.focal_length_mm;
  T v[3] = {pupil_shift_x - focal_xy[0], -focal_xy[1], pupil_height};
  const T n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int i = 0; i < 3; ++i) up[i] = v[i] / n;
}

// HeadParamsT<double> of a geometry and a beam.
HeadParamsT<double> ParamsOf(const HeadGeometry& geometry, const BeamPath& beam = {});

class ScanOptics {
 public:
  explicit ScanOptics(const HeadGeometry& geometry) : g_(geometry) {}

  ChiefRay Trace(const MirrorAngles& angles, const BeamPath& beam = {}) const;

  // The mirror angles whose chief ray passes through (x_mm, y_mm) at height z_mm (Newton
  // iteration from the paraxial guess). Returns false if it does not converge (far outside
  // the field).
  bool Solve(double x_mm, double y_mm, double z_mm, MirrorAngles* angles,
             const BeamPath& beam = {}) const;

  const HeadGeometry& geometry() const { return g_; }

 private:
  HeadGeometry g_;
};

// A head as a whole, command to beam: its controller maps a command to mirror angles by
// inverting the design geometry (the factory correction), the mirrors carry zero errors, and
// the as-built optics decide where the beam goes. design == built and zero offsets 0: a
// perfectly corrected head, every command lands where it asks.
struct HeadModel {
  HeadGeometry design;
  HeadGeometry built;
  double x_zero_offset_mrad = 0.0;  // optical angle
  double y_zero_offset_mrad = 0.0;

  Status Validate() const;
  // The mirror angles the controller sets for a command (x, y, focus z; galvo frame, mm),
  // zero errors included. False if the design inversion does not converge.
  bool CommandAngles(const Eigen::Vector3d& command, MirrorAngles* angles) const;
  // The chief ray of `beam` for a command. False as CommandAngles.
  bool Land(const Eigen::Vector3d& command, const BeamPath& beam, ChiefRay* ray) const;
  // Where the beam's chief ray crosses the command's own focus height.
  bool Spot(const Eigen::Vector3d& command, const BeamPath& beam, Eigen::Vector3d* spot) const;
  // The command whose chief ray of `beam` passes through target (x, y) at height target.z
  // (the command's z is target.z): the correction that makes the head land where asked.
  // False if it does not converge within 1e-7 mm.
  bool CommandFor(const Eigen::Vector3d& target, const BeamPath& beam,
                  Eigen::Vector3d* command) const;
};

}  // namespace insitu::optics
