// From placed 2D segments to a 3D galvo list on the measured surface (seed 000 sec. 2.4 and
// 3.3): every segment is cut into steps of at most max_step_mm, each point takes the height
// of the surface there (geometry::SurfaceModel) and the list marks through them in focus.
// Where the surface has no height (nothing measured nearby, or an edge inside the search
// radius) the mark stops and the point is reported; the next measured point starts a new mark
// with a jump. Nothing is marked at an invented height.
#pragma once

#include <functional>
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
  // The marking beam's direction (unit, toward the head) for a command at a point: with a
  // focus offset, the focus is put on the beam through the surface point, this far along it,
  // so the beam still meets the surface where the pattern is (off the field's centre the beam
  // comes in slanted: 10 mm of defocus 30 mm off axis would move the mark ~1 mm). Empty:
  // straight up.
  std::function<Eigen::Vector3d(const Eigen::Vector3d&)> beam_up;

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

// Equal-arc-length mapping (seed 000 sec. 3.3, case 3): a pattern keeps its size on a curved
// surface instead of being projected straight down (which shrinks it on the surface by the
// cosine of the slope). Each placed point's offset from `anchor_mm` along galvo x becomes an
// arc length along the measured surface's section y = anchor.y, and its offset along y one
// along the section x = anchor.x. Exact for surfaces curved in one direction (cylinders, such
// as the seed's arc), an approximation for doubly curved ones. Segments are first cut into
// steps of at most max_step_mm so the mapped path bends with the surface. Beyond the measured
// section the mapping continues at the last measured slope (those points then find no surface
// and are not marked). Galvo frame, mm.
// Errors: invalid_argument for max_step_mm <= 0; failed_precondition when the surface has no
// height at the anchor.
Result<std::vector<Segment2>> WrapOnSurface(const std::vector<Segment2>& placed,
                                            const Eigen::Vector2d& anchor_mm,
                                            const geometry::SurfaceModel& surface,
                                            double max_step_mm);

// Errors: invalid_argument for bad settings; failed_precondition when no point of the pattern
// lies on measured surface (the pattern is not on the part).
Result<std::vector<ListCommand>> PlanMarking(const std::vector<Segment2>& segments,
                                             const geometry::SurfaceModel& surface,
                                             const MarkSettings& settings,
                                             MarkPlanReport* report);

}  // namespace insitu::pattern
