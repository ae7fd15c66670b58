#include "insitu/pattern/mark_plan.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace insitu::pattern {

Status MarkSettings::Validate() const {
  if (!(jump_speed_mm_per_s > 0)) return InvalidArgument("jump_speed_mm_per_s must be > 0");
  if (!(mark_speed_mm_per_s > 0)) return InvalidArgument("mark_speed_mm_per_s must be > 0");
  if (!(laser_power >= 0 && laser_power <= 1))
    return InvalidArgument("laser_power must be in [0, 1]");
  if (!(laser_frequency_khz > 0)) return InvalidArgument("laser_frequency_khz must be > 0");
  if (!(max_step_mm > 0)) return InvalidArgument("max_step_mm must be > 0");
  if (!std::isfinite(focus_offset_mm)) return InvalidArgument("focus_offset_mm must be a number");
  for (double d : {laser_off_delay_us, jump_delay_us, mark_delay_us, polygon_delay_us}) {
    if (!(d >= 0)) return InvalidArgument("laser-off, jump, mark and polygon delays must be >= 0");
  }
  if (!std::isfinite(laser_on_delay_us))
    return InvalidArgument("laser_on_delay_us must be a number");
  return Status::Ok();
}

Result<std::vector<ListCommand>> PlanMarking(const std::vector<Segment2>& segments,
                                             const geometry::SurfaceModel& surface,
                                             const MarkSettings& s, MarkPlanReport* report) {
  INSITU_RETURN_IF_ERROR(s.Validate());
  MarkPlanReport r;
  r.segments = static_cast<int>(segments.size());
  r.z_min_mm = std::numeric_limits<double>::infinity();
  r.z_max_mm = -std::numeric_limits<double>::infinity();
  ListBuilder b;
  b.SetJumpSpeed(s.jump_speed_mm_per_s)
      .SetMarkSpeed(s.mark_speed_mm_per_s)
      .SetLaserDelays(s.laser_on_delay_us, s.laser_off_delay_us)
      .SetScannerDelays(s.jump_delay_us, s.mark_delay_us, s.polygon_delay_us)
      .SetLaserPower(s.laser_power)
      .SetLaserFrequency(s.laser_frequency_khz);
  bool in_mark = false;  // the previous point was on the surface and the beam is there
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  Eigen::Vector2d last_end(std::numeric_limits<double>::quiet_NaN(), 0.0);
  for (const Segment2& seg : segments) {
    const double length = (seg.b - seg.a).norm();
    const int steps = std::max(1, static_cast<int>(std::ceil(length / s.max_step_mm)));
    // A segment starting where the last one ended continues the same mark (a
    // polyline, or a hatch line cut into pieces): no jump, the laser stays on.
    const bool continues = in_mark && (seg.a - last_end).norm() < 1e-9;
    if (!continues) in_mark = false;
    last_end = seg.b;
    for (int i = continues ? 1 : 0; i <= steps; ++i) {
      const Eigen::Vector2d p = seg.a + (seg.b - seg.a) * (static_cast<double>(i) / steps);
      ++r.points;
      const auto at = surface.At(p.x(), p.y());
      if (!at) {
        ++r.points_without_surface;
        r.unmarked_mm.push_back(p);
        in_mark = false;
        continue;
      }
      Eigen::Vector3d q(p.x(), p.y(), at->z_mm + s.focus_offset_mm);
      if (s.focus_offset_mm != 0.0 && s.beam_up) {
        // The focus on the beam through the surface point (the beam's slant varies slowly over
        // the field: three rounds settle it to well under a micrometre).
        const Eigen::Vector3d surface_point(p.x(), p.y(), at->z_mm);
        for (int it = 0; it < 3; ++it) {
          const Eigen::Vector3d up = s.beam_up(q);
          if (!(up.allFinite() && up.z() > 0.1)) break;
          q = surface_point + up * (s.focus_offset_mm / up.z());
        }
      }
      r.z_min_mm = std::min(r.z_min_mm, at->z_mm);
      r.z_max_mm = std::max(r.z_max_mm, at->z_mm);
      if (in_mark) {
        b.MarkAbs(q);
        ++r.marks;
        r.marked_length_mm += (q - previous).head<2>().norm();
      } else {
        b.JumpAbs(q);
      }
      previous = q;
      in_mark = true;
    }
  }
  if (report) *report = r;
  if (r.marks == 0) {
    return FailedPrecondition("no part of the pattern lies on measured surface (" +
                              std::to_string(r.points_without_surface) + " of " +
                              std::to_string(r.points) +
                              " points without a height): place it "
                              "on the scanned part");
  }
  return b.Finish();
}

namespace {

// Arc length along a straight section of the surface through `anchor` in
// direction `dir` (unit, xy): a table of (offset along dir, arc length),
// marched both ways in steps of h.
class Section {
 public:
  Section(const geometry::SurfaceModel& surface, const Eigen::Vector2d& anchor,
          const Eigen::Vector2d& dir, double reach)
      : anchor_(anchor), dir_(dir) {
    constexpr double h = 0.05;  // mm: the sagitta error of a chord on R = 25 mm is 1e-5 mm
    const auto z0 = surface.At(anchor.x(), anchor.y());
    for (int side : {1, -1}) {
      std::vector<std::pair<double, double>>& t = side > 0 ? pos_ : neg_;
      t.push_back({0.0, 0.0});
      double z = z0 ? z0->z_mm : 0.0, s = 0.0, ratio = 1.0;
      for (double d = h; d <= reach + h; d += h) {
        const Eigen::Vector2d p = anchor + side * d * dir;
        const auto q = surface.At(p.x(), p.y());
        if (!q) break;
        const double ds = std::hypot(h, q->z_mm - z);
        ratio = ds / h;
        s += ds;
        z = q->z_mm;
        t.push_back({d, s});
      }
      last_ratio_[side > 0] = ratio;
    }
  }

  // Offset along dir (signed) whose arc length from the anchor is u (signed).
  double OffsetFor(double u) const {
    const auto& t = u >= 0 ? pos_ : neg_;
    const double a = std::abs(u);
    const auto it = std::lower_bound(t.begin(), t.end(), a,
                                     [](const auto& e, double v) { return e.second < v; });
    double d;
    if (it == t.end()) {
      d = t.back().first + (a - t.back().second) / last_ratio_[u >= 0];  // beyond: last slope
    } else if (it == t.begin()) {
      d = 0.0;
    } else {
      const auto& lo = *(it - 1);
      d = lo.first + (a - lo.second) / (it->second - lo.second) * (it->first - lo.first);
    }
    return u >= 0 ? d : -d;
  }

 private:
  Eigen::Vector2d anchor_, dir_;
  std::vector<std::pair<double, double>> pos_, neg_;
  double last_ratio_[2] = {1.0, 1.0};
};

}  // namespace

Result<std::vector<Segment2>> WrapOnSurface(const std::vector<Segment2>& placed,
                                            const Eigen::Vector2d& anchor,
                                            const geometry::SurfaceModel& surface,
                                            double max_step_mm) {
  if (!(max_step_mm > 0)) return InvalidArgument("wrap: max_step_mm must be > 0");
  if (!surface.At(anchor.x(), anchor.y())) {
    return FailedPrecondition("wrap: no measured surface at the pattern's anchor (" +
                              std::to_string(anchor.x()) + ", " + std::to_string(anchor.y()) +
                              ") mm");
  }
  double reach = 0.0;
  for (const Segment2& s : placed) {
    reach = std::max(
        {reach, (s.a - anchor).cwiseAbs().maxCoeff(), (s.b - anchor).cwiseAbs().maxCoeff()});
  }
  const Section along_x(surface, anchor, Eigen::Vector2d::UnitX(), reach);
  const Section along_y(surface, anchor, Eigen::Vector2d::UnitY(), reach);
  const auto map = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector2d d = p - anchor;
    return Eigen::Vector2d(anchor.x() + along_x.OffsetFor(d.x()),
                           anchor.y() + along_y.OffsetFor(d.y()));
  };
  std::vector<Segment2> out;
  out.reserve(placed.size());
  for (const Segment2& s : placed) {
    const int n = std::max(1, static_cast<int>(std::ceil((s.b - s.a).norm() / max_step_mm)));
    Eigen::Vector2d prev = map(s.a);
    for (int k = 1; k <= n; ++k) {
      const Eigen::Vector2d next = map(s.a + (s.b - s.a) * (static_cast<double>(k) / n));
      out.push_back({prev, next});
      prev = next;
    }
  }
  return out;
}

}  // namespace insitu::pattern
