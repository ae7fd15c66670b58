// Where a surface ends along a scan line, from the stripe points on it.
//
// The stripe on a top surface fades out over the last few columns before its end: as the beam
// passes the edge, a falling share of its light still reaches the top. The edge is where the
// stripe has half its brightness on the top (a symmetric beam centred on the edge puts half
// its light on each side). The outermost points alone would not do: how far the faint tail
// reaches depends on the beam width and on which columns still pass the extraction's
// thresholds (measured on the step gauge: +0.1 to +0.2 mm on 80 mm).
#pragma once

#include <vector>

namespace insitu::inspect {

struct LinePoint {
  double x = 0.0;  // mm, galvo frame; the line runs along y
  double y = 0.0;
  double z = 0.0;
  double intensity = 0.0;  // stripe signal above the local background, gray levels
};

// Sorts by y.
void SortAlongLine(std::vector<LinePoint>* points);

// Median y spacing of points[first..last] (sorted); 0 if fewer than two.
double MedianSpacing(const std::vector<LinePoint>& points, int first, int last);

// The y of the surface's end near index `end` of points sorted along y, walking inward in
// direction `dir` (+1 from a low end, -1 from a high end) and never past index `limit`
// (inclusive; -1: the far end of the vector). The reference brightness is the median peak of
// up to 20 points beyond the first 8 (the fading zone of a ~0.5 mm beam over ~0.08 mm
// columns); the end is interpolated between the last point at or above half of it and the
// next one out, or put half a spacing out when nothing was measured beyond.
double HalfBrightnessEnd(const std::vector<LinePoint>& points, int end, int dir, double spacing,
                         int limit = -1);

}  // namespace insitu::inspect
