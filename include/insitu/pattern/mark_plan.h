// From placed 2D segments to a 3D galvo list on the measured surface (seed 000 sec. 2.4 and
// 3.3): every segment is cut into steps of at most max_step_mm, each point takes the height
// of the surface there (geometry::SurfaceModel) and the list marks through them in focus.
// Where the surface has no height (nothing measured nearby, or an edge inside the search
// radius) the mark stops and the point is reported; the next measured point starts a new mark
// with a jump. Nothing is marked at an invented height.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/geometry/surface.h"
#include "insitu/pattern/galvo_list.h"
#include "insitu/pattern/raster.h"

namespace insitu::pattern {

struct MarkSettings {
  double jump_speed_mm_per_s = 5000.0;
  double mark_speed_mm_per_s = 1000.0;
  double laser_power = 0.5;             // fraction
  double laser_frequency_khz = 30.0;
  double laser_on_delay_us = 100.0, laser_off_delay_us = 120.0;
  double jump_delay_us = 100.0, mark_delay_us = 50.0, polygon_delay_us = 20.0;
  double max_step_mm = 0.2;             // so z follows the surface between points
  double focus_offset_mm = 0.0;         // focus this far above (+) the surface

  Status Validate() const;
};

struct MarkPlanReport {
  int segments = 0;                     // placed segments in
  int marks = 0;                        // mark_abs commands out
  int points = 0;                       // surface points queried
  int points_without_surface = 0;       // of those, no height: not marked
  std::vector<Eigen::Vector2d> unmarked_mm;  // where (every point without surface)
  double marked_length_mm = 0.0;
  double z_min_mm = 0.0, z_max_mm = 0.0;     // heights the marks follow
};

// Errors: invalid_argument for bad settings; failed_precondition when no point of the pattern
// lies on measured surface (the pattern is not on the part).
Result<std::vector<ListCommand>> PlanMarking(const std::vector<Segment2>& segments,
                                             const geometry::SurfaceModel& surface,
                                             const MarkSettings& settings,
                                             MarkPlanReport* report);

}  // namespace insitu::pattern
