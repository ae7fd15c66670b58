// After marking: looking at what was marked and comparing it with the design
// (internal to the job module).
//
// - Placement and size, with the side camera: a frame before and one after
// marking (pointer
//   off, same exposure); the pixels that darkened are the marks. Each is traced
//   back through the calibrated camera onto the measured surface (galvo frame),
//   and the darkening-weighted centroid and rms radius of the marks are
//   compared with the design's (length-weighted over its placed segments:
//   hatching covers an area uniformly).
// - Line spacing and width, with the scan head's coaxial camera: the head aims
// at spots that
//   the design hatches fully over several lines; each image is measured across
//   the lines (vision::MeasureHatch). The camera's scale and rotation are its
//   lens data (job file).
// - Focus, with the coaxial camera too: it shares the focusing optics, so a
// sweep of the
//   dynamic focus at a marked point is sharpest where the surface really is.
//   The focus error is the list's focus there minus that height.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/calib/calibration.h"
#include "insitu/core/frame.h"
#include "insitu/core/status.h"
#include "insitu/geometry/surface.h"
#include "insitu/hw/machine.h"
#include "insitu/job/report.h"
#include "insitu/pattern/raster.h"

namespace insitu::job {

struct VerifyOptions {
  bool enabled = true;
  double coaxial_pixel_um = 5.0;      // the coaxial camera's scale on the part (lens data)
  double coaxial_rotation_deg = 0.0;  // its sensor's x against galvo x
  double coaxial_exposure_ms = 2.0;
  int spacing_spots = 3;        // places where the line spacing is measured
  int focus_points = 5;         // marked points where the focus is swept
  double focus_sweep_mm = 0.6;  // +- around the list's focus
  double focus_step_mm = 0.1;
  double side_target_level = 160.0;  // side camera auto-exposure: grey of the bare part

  Status Validate() const;
};

// One pattern as placed on the part.
struct ItemDesign {
  std::vector<pattern::Segment2> placed;  // galvo xy, mm: everything marked
  double spacing_mm = 0.0;                // hatch spacing asked for (0: no hatching)
  double hatch_angle_deg = 0.0;           // first hatch direction, galvo xy
};

struct MarkDesign {
  std::vector<ItemDesign> items;             // apart from each other on the part
  std::vector<Eigen::Vector3d> mark_points;  // the list's mark points (focus z)
};

// A side-camera frame with the pointer off, exposed so the bare part reads
// about side_target_level (the exposure is kept for the frame after marking).
Result<Frame> GrabSideView(hw::Machine& machine, const VerifyOptions& options, double* exposure_us);

// Measures the marks and fills report metrics (placement_error_mm and
// pattern_size_error_pct, the worst item; line_spacing_um, line_spacing_std_um
// and line_width_um of the first hatched item and line_spacing_<asked>_um, ...
// for every spacing asked, e.g. line_spacing_40_um; focus_error_max_mm, ...),
// artifacts (mark.png, coaxial.png) and warnings. A measurement that cannot be
// made is a warning, not a failure: the marks are already on the part.
Status VerifyMarks(hw::Machine& machine, const calib::CalibrationSet& calibration,
                   const geometry::SurfaceModel& surface, const MarkDesign& design,
                   const VerifyOptions& options, const Frame& before, const Frame& after,
                   const std::string& out_dir, Report* report);

}  // namespace insitu::job
