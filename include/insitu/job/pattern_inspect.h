// `insitu pattern inspect FILE`: what a vector drawing will mark, before any machine moves:
// its extents and units, what the reader drew and what it skipped (by kind), the closed areas
// the hatch fills, and a preview picture of the outlines and the hatch at scale.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/pattern/vector.h"

namespace insitu::job {

struct PatternInspectOptions {
  double scale = 1.0;              // as a mark job's placement.scale
  double hatch_spacing_mm = 0.04;  // on the part, as a mark job's hatch.spacing_mm
  std::vector<double> hatch_angles_deg{0.0};
  double tolerance_mm = 0.005;     // curve flattening
  std::string preview_path;        // PNG to write; empty: none

  Status Validate() const;
};

struct PatternInspection {
  pattern::VectorPattern pattern;  // as read, at the options' scale
  Eigen::Vector2d lo = Eigen::Vector2d::Zero(), hi = Eigen::Vector2d::Zero();  // extents, mm
  int closed_paths = 0, open_paths = 0;
  double outline_length_mm = 0.0;
  // What the hatch marks: its line length, and the area it fills (length x spacing), the
  // closed paths' area by the even-odd rule as the marking sees it.
  double hatch_length_mm = 0.0;
  double filled_area_mm2 = 0.0;
  std::string preview_path;  // written, if asked for
};

// Reads `path` (.svg, .dxf, .plt/.hpgl) and hatches it as a mark job would. Errors: the
// reader's (parse_error, not_found, invalid_argument), invalid_argument for bad options,
// and the preview's write error.
Result<PatternInspection> InspectPattern(const std::string& path,
                                         const PatternInspectOptions& options);

// The inspection as the command prints it: a few lines, counts by kind, warnings last.
std::string FormatInspection(const std::string& path, const PatternInspection& inspection);

}  // namespace insitu::job
