// Path optimisation of dense vector polylines (seed 004): a dense, unevenly spaced polyline (a
// PLT outline, say) becomes a few straight lines and cubic Beziers, which are then cut into
// mark points whose spacing follows the output scale and the local curvature. A dense polyline
// marked point by point makes the galvo dwell on every point (ablation at low magnification);
// a sparse one shows facets at high magnification. This fixes both.
//
// Frames and units: the input polyline and every fit tolerance are in input units (pattern
// coordinates; the seed's "pixels"). `scale_mm_per_unit` (the seed's magnification: 0.06 mm per
// pixel at 36x, 0.12 at 72x) takes input units to mark mm about the pattern origin; the emitted
// mark points are in mm.
//
// Steps (seed 004 section 1):
//   1. thinning (eq. 1-2): greedy longest chords that keep every skipped point within eps_line;
//   2. curve sets (eq. 3): runs of thinned points turning by less than acos(curve_cos_min) per
//      point, without a chord line_length_ratio times longer than its neighbour (a straight
//      line), split where the curvature changes sign and into pieces that turn their tangent
//      by less than 90 degrees; a set of fewer than 4 points stays thinned lines;
//   3. each piece is fitted with one cubic whose inner control points lie on the end tangents
//      (estimated from the points) at the same fraction t of the way to their intersection Q,
//      t by bisection on the signed error sum (eq. 4); a fit worse than e_per is split where
//      it crosses the data and both halves are refitted (sharing the tangent at the cut).
//      Parallel or diverging end tangents split the piece at its middle; a piece too short
//      for a cubic, or straight within eps_line, becomes thinned lines;
//   4. output (eq. 5-6): each run of entities joined without a corner is cut into the longest
//      chords whose deviation from the curve stays within chord_error_mm (see Placement);
//      corners and the ends of straight lines are emitted exactly.
//
// Error budget: the fit keeps every input point within max(eps_line, e_per) of the fitted path
// and the fitted path within that distance of the input polyline; the output keeps every chord
// within chord_error_mm of the fitted path and the other way round. So the Hausdorff distance
// between the scaled input and the emitted polyline is at most
//   ErrorBoundMm() = max(eps_line, e_per) * scale_mm_per_unit + chord_error_mm,
// and PathOptOptions::ForErrorBudget splits a total the caller asks for between the two. The
// curve-side checks sample the curves (3 points between successive input points, 16 along a
// chord, against limits shrunk by what a smooth deviation can hide between samples), so the
// bound is checked rather than proven: OptimisePolyline measures the actual distance.
//
// Cost: about 5 ms for 1181 points, and 3-5 ms more for the error measurement of
// OptimisePolyline (bench/path_bench.cc).
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/pattern/vector.h"

namespace insitu::pattern {

struct PathOptOptions {
  // Fit tolerances, input units.
  double eps_line = 0.005;  // thinning: max distance of a dropped point from its chord (eq. 2)
  double e_per = 0.005;     // max distance between a Bezier and the points it replaces
  double eps_s = 0.005;     // the bisection on t stops when |signed error sum| < eps_s (eq. 4)
  // Curve-set criteria (eq. 3; the seed's values).
  double curve_cos_min = 0.95;     // cos of the largest turn between successive chords
  double line_length_ratio = 3.0;  // a chord this much longer than its neighbour is a line
  // Output.
  double scale_mm_per_unit = 1.0;  // mark mm per input unit (> 0)
  double chord_error_mm = 0.001;   // max distance of an emitted chord from the fitted path
  // Where the mark points of a curve go (lines and corners always emit their exact points).
  enum class Placement {
    // On the curve; each chord is the longest whose chord height (largest distance of the
    // arc from it) is at most chord_error_mm: the quantity seed eq. (5) estimates.
    kOnCurve,
    // On the curve, and seed eq. (5) literally as well: |chord midpoint - P(mid parameter)|
    // <= chord_error_mm. The triangle-fitted cubics run at uneven parameter speed, so this
    // also counts a shift along the curve and costs about 30% more marks for no accuracy.
    kOnCurveSeedMidpoint,
    // Up to chord_error_mm outside the curve (its convex side), chords within chord_error_mm
    // of the arc on both sides: about 1/sqrt(2) of the kOnCurve marks within the same bound.
    // Not in the seed; the mark points are then off the fitted curve (by < chord_error_mm).
    kToleranceBand,
  };
  Placement placement = Placement::kOnCurve;

  // Invalid argument naming the first field that is not finite and positive, or out of range
  // (curve_cos_min in (0, 1), line_length_ratio > 1).
  Status Validate() const;

  // The guaranteed bound on the distance between the scaled input and the emitted polyline.
  double FitErrorMm() const;
  double ErrorBoundMm() const { return FitErrorMm() + chord_error_mm; }

  // Options for a total error of `max_error_mm` at `scale_mm_per_unit`: a quarter of it to the
  // fit (eps_line = e_per = eps_s), three quarters to the chords, which set the mark count.
  static PathOptOptions ForErrorBudget(double scale_mm_per_unit, double max_error_mm);
};

// A straight line or a cubic Bezier, input units. A line uses control[0] and control[3] (its
// inner control points sit at its thirds, so it evaluates as a cubic too).
struct PathEntity {
  enum class Kind { kLine, kCubic };
  Kind kind = Kind::kLine;
  std::array<Eigen::Vector2d, 4> control = {Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(),
                                            Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};
  // The entity continues the previous one inside one smooth curve (a cubic split where the
  // tangent is shared, or a short line standing in for a nearly straight bit of it), so the
  // output may run a chord across the joint. False at corners and for the thinned straight
  // lines of step 2, whose end points are always marked.
  bool smooth_start = false;

  Eigen::Vector2d Evaluate(double u) const;  // u in [0, 1] (eq. 6)
};

// Entities joined end to start; when closed, the last one ends where the first starts.
struct OptimisedPath {
  std::vector<PathEntity> entities;
  bool closed = false;
  // Distinct control points (shared end points counted once): the seed's "control points".
  int ControlPoints() const;
};

// Steps 1-3. Repeated successive points count once. A closed polyline whose first point is no
// corner is re-started at its sharpest corner (the same outline; the marks then begin there),
// so that no curve is cut at an arbitrary point. Errors: invalid_argument for invalid options,
// fewer than 2 distinct points, or a point that is not finite (its index is named).
Result<OptimisedPath> FitPath(const Polyline& polyline, const PathOptOptions& options);

// Step 4: mark points in mm (input scaled by scale_mm_per_unit); closed when the path is (the
// first point is not repeated at the end). Empty for options that fail Validate().
Polyline Interpolate(const OptimisedPath& path, const PathOptOptions& options);

struct PathOptSummary {
  int input_points = 0;
  int control_points = 0;
  int mark_points = 0;
  int lines = 0;  // line entities: straight edges, and short stand-ins inside curves
  int cubics = 0;
  double error_bound_mm = 0;  // options.ErrorBoundMm()
  // Measured Hausdorff distance between the scaled input and the emitted polyline, both
  // directions: an upper bound at most 0.1% of error_bound_mm above the true value.
  double max_error_mm = 0;
};

struct OptimisedMarks {
  Polyline marks;  // mm
  OptimisedPath path;
  PathOptSummary summary;
};

// FitPath, then Interpolate, then the measured error. Errors: those of FitPath.
Result<OptimisedMarks> OptimisePolyline(const Polyline& polyline, const PathOptOptions& options);

// Directed Hausdorff distance: the largest distance from a point of polyline `from` (its
// segments included) to polyline `to`, both in the same units. The result is an upper bound at
// most `tolerance` (> 0, same units) above the true value. A single point counts as a polyline;
// infinity when either is empty.
double DirectedHausdorff(const Polyline& from, const Polyline& to, double tolerance);

}  // namespace insitu::pattern
