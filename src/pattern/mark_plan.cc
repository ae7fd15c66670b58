#include "insitu/pattern/mark_plan.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace insitu::pattern {

Status MarkSettings::Validate() const {
  if (!(jump_speed_mm_per_s > 0)) return InvalidArgument("jump_speed_mm_per_s must be > 0");
  if (!(mark_speed_mm_per_s > 0)) return InvalidArgument("mark_speed_mm_per_s must be > 0");
  if (!(laser_power >= 0 && laser_power <= 1)) return InvalidArgument("laser_power must be in [0, 1]");
  if (!(laser_frequency_khz > 0)) return InvalidArgument("laser_frequency_khz must be > 0");
  if (!(max_step_mm > 0)) return InvalidArgument("max_step_mm must be > 0");
  if (!std::isfinite(focus_offset_mm)) return InvalidArgument("focus_offset_mm must be a number");
  for (double d : {laser_off_delay_us, jump_delay_us, mark_delay_us, polygon_delay_us}) {
    if (!(d >= 0)) return InvalidArgument("laser-off, jump, mark and polygon delays must be >= 0");
  }
  if (!std::isfinite(laser_on_delay_us)) return InvalidArgument("laser_on_delay_us must be a number");
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
  for (const Segment2& seg : segments) {
    const double length = (seg.b - seg.a).norm();
    const int steps = std::max(1, static_cast<int>(std::ceil(length / s.max_step_mm)));
    bool in_mark = false;  // the previous point was on the surface and the beam is there
    Eigen::Vector3d previous = Eigen::Vector3d::Zero();
    for (int i = 0; i <= steps; ++i) {
      const Eigen::Vector2d p = seg.a + (seg.b - seg.a) * (static_cast<double>(i) / steps);
      ++r.points;
      const auto at = surface.At(p.x(), p.y());
      if (!at) {
        ++r.points_without_surface;
        r.unmarked_mm.push_back(p);
        in_mark = false;
        continue;
      }
      const Eigen::Vector3d q(p.x(), p.y(), at->z_mm + s.focus_offset_mm);
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
                              std::to_string(r.points) + " points without a height): place it "
                              "on the scanned part");
  }
  return b.Finish();
}

}  // namespace insitu::pattern
