#include "insitu/pattern/spiral_target.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace insitu::pattern {
namespace {

constexpr size_t kMaxPoints = 2000000;

// Angle a chord may turn through on a curve of radius of curvature `rho` while its sagitta
// stays within `tol`: rho (1 - cos(phi / 2)) = tol. Capped at a quarter turn so even a coarse
// tolerance keeps the polyline a recognisable spiral.
double TurnForSagitta(double rho, double tol) {
  if (tol >= rho) return 0.5 * M_PI;
  return std::min(0.5 * M_PI, 2.0 * std::acos(1.0 - tol / rho));
}

}  // namespace

Status SpiralTargetOptions::Validate() const {
  if (!(diameter_mm > 0) || !(pitch_mm > 0) || !(chord_tolerance_mm > 0)) {
    return InvalidArgument(
        "spiral target: diameter_mm, pitch_mm and chord_tolerance_mm must be "
        "> 0, got " +
        std::to_string(diameter_mm) + ", " + std::to_string(pitch_mm) + ", " +
        std::to_string(chord_tolerance_mm));
  }
  if (diameter_mm < 2.0 * pitch_mm) {
    return InvalidArgument("spiral target: diameter_mm " + std::to_string(diameter_mm) +
                           " is less than two line widths (pitch_mm " + std::to_string(pitch_mm) +
                           ")");
  }
  if (chord_tolerance_mm > 0.25 * pitch_mm) {
    return InvalidArgument("spiral target: chord_tolerance_mm " +
                           std::to_string(chord_tolerance_mm) +
                           " exceeds a quarter of pitch_mm; the turns would not touch");
  }
  return Status::Ok();
}

double SpiralOuterPathRadius(const SpiralTargetOptions& options) {
  return 0.5 * (options.diameter_mm - options.pitch_mm);
}

Result<std::vector<Eigen::Vector2d>> SpiralTargetPath(const SpiralTargetOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  const double a = o.pitch_mm / (2.0 * M_PI);  // r = a theta
  const double r_out = SpiralOuterPathRadius(o);
  const double theta_end = r_out / a;
  const double tol = o.chord_tolerance_mm;
  const auto too_many = [&]() {
    return InvalidArgument("spiral target: chord_tolerance_mm " + std::to_string(tol) +
                           " needs more than " + std::to_string(kMaxPoints) + " points");
  };

  std::vector<Eigen::Vector2d> points;
  points.emplace_back(0.0, 0.0);
  double theta = 0.0;
  while (theta < theta_end) {
    const double r = a * theta;
    // Archimedean spiral: radius of curvature (r^2 + a^2)^(3/2) / (r^2 + 2 a^2), increasing
    // with r (from a / 2 at the centre), so its value at the start of a step bounds the whole
    // step from below: an arc no longer than rho * phi, never more curved than 1 / rho, stays
    // within rho (1 - cos(phi / 2)) of its chord. Arc length ds = sqrt(r^2 + a^2) dtheta grows
    // along the step, so the step is sized with the speed at its far end (one fixed-point
    // pass: that end is nearer than the first guess's, where the speed is higher still).
    const double speed = std::sqrt(r * r + a * a);
    const double rho = speed * speed * speed / (r * r + 2.0 * a * a);
    const double arc = TurnForSagitta(rho, tol) * rho;
    const double guess_r = a * (theta + arc / speed);
    const double dtheta = arc / std::sqrt(guess_r * guess_r + a * a);
    theta = std::min(theta_end, theta + dtheta);
    const double rr = a * theta;
    points.emplace_back(rr * std::cos(theta), rr * std::sin(theta));
    if (points.size() > kMaxPoints) return too_many();
  }
  // The closing circle at r_out, one full turn from where the spiral arrived.
  const int n = std::max(8, static_cast<int>(std::ceil(2.0 * M_PI / TurnForSagitta(r_out, tol))));
  if (points.size() + n > kMaxPoints) return too_many();
  const Eigen::Vector2d arrival = points.back();
  for (int k = 1; k < n; ++k) {
    const double t = theta_end + 2.0 * M_PI * k / n;
    points.emplace_back(r_out * std::cos(t), r_out * std::sin(t));
  }
  points.push_back(arrival);
  return points;
}

Status CrossTargetOptions::Validate() const {
  if (!(length_mm > 0) || !(bar_width_mm > 0) || !(line_width_mm > 0)) {
    return InvalidArgument("cross target: length_mm, bar_width_mm and line_width_mm must be > 0");
  }
  if (bar_width_mm < line_width_mm) {
    return InvalidArgument("cross target: bar_width_mm " + std::to_string(bar_width_mm) +
                           " is narrower than one line (line_width_mm " +
                           std::to_string(line_width_mm) + ")");
  }
  if (length_mm <= bar_width_mm) {
    return InvalidArgument("cross target: length_mm " + std::to_string(length_mm) +
                           " must exceed bar_width_mm " + std::to_string(bar_width_mm));
  }
  return Status::Ok();
}

Result<std::vector<Segment2>> CrossTargetStrokes(const CrossTargetOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  // A relative slack so that a width that is an exact multiple of the line width does not get
  // an extra stroke from rounding.
  const int n = std::max(1, static_cast<int>(std::ceil(o.bar_width_mm / o.line_width_mm - 1e-9)));
  const double half_len = 0.5 * (o.length_mm - o.line_width_mm);
  const double span = o.bar_width_mm - o.line_width_mm;  // between the outer strokes' centres
  std::vector<Segment2> strokes;
  strokes.reserve(2 * n);
  for (int bar = 0; bar < 2; ++bar) {
    for (int k = 0; k < n; ++k) {
      const double offset = n == 1 ? 0.0 : -0.5 * span + span * k / (n - 1);
      const double dir = k % 2 == 0 ? 1.0 : -1.0;
      Segment2 s;
      if (bar == 0) {
        s.a = Eigen::Vector2d(-dir * half_len, offset);
        s.b = Eigen::Vector2d(dir * half_len, offset);
      } else {
        s.a = Eigen::Vector2d(offset, -dir * half_len);
        s.b = Eigen::Vector2d(offset, dir * half_len);
      }
      strokes.push_back(s);
    }
  }
  return strokes;
}

}  // namespace insitu::pattern
