// Marked calibration targets for measuring the galvo field with a camera.
//
// The spiral-filled circle of seed 003 (sec. 2.2, Fig. 8c and 9): an Archimedean spiral from
// the disc's centre outward whose pitch equals the marked line width, so adjacent turns touch
// and the disc is filled in one continuous stroke. Unlike parallel-line hatching the galvo never
// stops or reverses inside the target, so the over-burn of acceleration and laser on/off is
// confined to the start at the centre, where a detector that looks only at the disc's outer
// boundary (seed 003: minimum enclosing circle of the outer contour) does not see it. The
// spiral ends with one full circle at the outer radius so the disc's edge is a single clean
// stroke.
//
// Seed 001's "+" (two bars, each marked as a few parallel strokes) is offered as a second
// target.
//
// Everything is in pattern coordinates (mm, y up), centred on the origin; place the targets in
// the galvo field with pattern::Place or by adding the target's position.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/pattern/raster.h"

namespace insitu::pattern {

struct SpiralTargetOptions {
  // Diameter of the marked disc: the outer edge of a line `pitch_mm` wide on the final circle.
  double diameter_mm = 2.5;
  // Radial growth per turn = the marked line width (seed 003: spacing equal to the line
  // width, so the disc is filled without gaps or double passes).
  double pitch_mm = 0.035;
  // Largest distance between the polyline and the ideal curve (chord error, mm).
  double chord_tolerance_mm = 0.001;

  // invalid_argument when a length is not positive, the disc is narrower than two line
  // widths, or the chord tolerance exceeds a quarter of the pitch (chords that far inside the
  // curve would open gaps between the turns).
  Status Validate() const;
};

// Radius of the path's closing circle: (diameter - pitch) / 2, so that a line `pitch_mm` wide
// drawn on it ends exactly at the disc's edge, diameter / 2.
double SpiralOuterPathRadius(const SpiralTargetOptions& options);

// The target as one polyline: the spiral r = pitch * theta / (2 pi) (theta from 0,
// counter-clockwise) from the centre (0, 0) out to SpiralOuterPathRadius, then one full circle
// at that radius ending on the point where the spiral reached it. Every point lies on the
// ideal curve; consecutive points are spaced so the chord between them stays within
// chord_tolerance_mm of the curve (step from the local radius of curvature, which only grows
// along the spiral). Errors: the options' Validate(); invalid_argument if the tolerance would
// need more than 2,000,000 points.
Result<std::vector<Eigen::Vector2d>> SpiralTargetPath(const SpiralTargetOptions& options);

struct CrossTargetOptions {
  double length_mm = 3.0;        // each bar, from one end of the marked line to the other
  double bar_width_mm = 0.12;    // across a bar, outer edge to outer edge of the marked lines
  double line_width_mm = 0.035;  // of one stroke; strokes are spaced at most this far apart

  // invalid_argument when a length is not positive, a bar is narrower than one line, or not
  // longer than it is wide.
  Status Validate() const;
};

// Seed 001's "+": a bar along x, then one along y, crossing at the origin. Each bar is
// n = ceil(bar_width / line_width) parallel strokes, evenly spaced so the outer strokes' edges
// lie at +-bar_width / 2 and (a line's ends being round, line_width / 2 in radius) their ends
// at +-length / 2; consecutive strokes run in opposite directions (short jumps). One stroke
// when bar_width equals line_width. Errors: the options' Validate().
Result<std::vector<Segment2>> CrossTargetStrokes(const CrossTargetOptions& options);

}  // namespace insitu::pattern
