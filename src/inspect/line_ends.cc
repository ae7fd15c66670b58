#include "inspect/line_ends.h"

#include <algorithm>
#include <cmath>

#include "insitu/core/robust.h"

namespace insitu::inspect {

void SortAlongLine(std::vector<LinePoint>* points) {
  std::sort(points->begin(), points->end(),
            [](const LinePoint& a, const LinePoint& b) { return a.y < b.y; });
}

double MedianSpacing(const std::vector<LinePoint>& points, int first, int last) {
  std::vector<double> gaps;
  for (int i = first + 1; i <= last; ++i) gaps.push_back(points[i].y - points[i - 1].y);
  if (gaps.empty()) return 0.0;
  return MedianInPlace(gaps);
}

double HalfBrightnessEnd(const std::vector<LinePoint>& points, int end, int dir, double spacing,
                         int limit) {
  constexpr int kSkip = 8;        // columns of the fading zone
  constexpr int kReference = 20;  // columns of full brightness for the reference
  const int n = static_cast<int>(points.size());
  if (limit < 0) limit = dir > 0 ? n - 1 : 0;
  auto inside = [&](int i) { return i >= 0 && i < n && (dir > 0 ? i <= limit : i >= limit); };
  std::vector<double> ref;
  for (int i = end + dir * kSkip; inside(i) && static_cast<int>(ref.size()) < kReference;
       i += dir) {
    ref.push_back(points[i].intensity);
  }
  if (ref.empty()) return points[end].y;
  const double half = 0.5 * MedianInPlace(ref);
  int k = end;  // first point from the end at or above half brightness
  while (k != end + dir * kSkip && inside(k) && points[k].intensity < half) k += dir;
  if (!inside(k)) return points[end].y;
  const int out = k - dir;  // the next point outward, below half brightness
  if (out >= 0 && out < n && std::abs(points[out].y - points[k].y) < 2.5 * spacing) {
    const double t = (points[k].intensity - half) / (points[k].intensity - points[out].intensity);
    return points[k].y + t * (points[out].y - points[k].y);
  }
  // Nothing measured beyond (the faint tail fell below the extraction's thresholds, or the
  // surface below took the column): extrapolate the fade of the last two points out to half
  // brightness, at most one spacing.
  const int in = k + dir;
  if (inside(in) && points[in].intensity > points[k].intensity &&
      std::abs(points[in].y - points[k].y) < 2.5 * spacing) {
    const double step = std::abs(points[in].y - points[k].y);
    const double beyond = (points[k].intensity - half) /
                          (points[in].intensity - points[k].intensity) * step;
    return points[k].y - dir * std::min(beyond, spacing);
  }
  return points[k].y - dir * 0.5 * spacing;
}

}  // namespace insitu::inspect
