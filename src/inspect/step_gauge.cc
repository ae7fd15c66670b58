#include "insitu/inspect/step_gauge.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <vector>

#include "inspect/line_ends.h"

namespace insitu::inspect {

Status StepGaugeSpec::Validate() const {
  if (heights_mm.empty()) return InvalidArgument("heights_mm must list at least one step");
  for (double h : heights_mm) {
    if (!(h > 0)) return InvalidArgument("heights_mm must all be > 0");
  }
  if (!(step_width_mm > 2 * edge_margin_mm)) {
    return InvalidArgument("step_width_mm must exceed twice edge_margin_mm");
  }
  if (!(length_mm > 2 * edge_margin_mm)) return InvalidArgument("length_mm must exceed twice edge_margin_mm");
  if (!(edge_margin_mm >= 0)) return InvalidArgument("edge_margin_mm must be >= 0");
  if (!(bin_mm > 0)) return InvalidArgument("bin_mm must be > 0");
  return Status::Ok();
}

namespace {

struct Extent {
  double y_min = std::numeric_limits<double>::infinity();
  double y_max = -std::numeric_limits<double>::infinity();
  int points = 0;
};

// Extent along y of one line's points on a step's top (sorted here).
Extent TopExtent(std::vector<LinePoint>* top) {
  SortAlongLine(top);
  Extent e;
  const int n = static_cast<int>(top->size());
  e.points = n;
  if (n < 2) return e;
  const double spacing = MedianSpacing(*top, 0, n - 1);
  e.y_min = HalfBrightnessEnd(*top, 0, +1, spacing);
  e.y_max = HalfBrightnessEnd(*top, n - 1, -1, spacing);
  return e;
}

}  // namespace

Result<StepGaugeResult> EvaluateStepGauge(const geometry::Cloud& cloud, const StepGaugeSpec& s) {
  INSITU_RETURN_IF_ERROR(s.Validate());
  const int n = static_cast<int>(s.heights_mm.size());
  const double x0 = s.center_x_mm - 0.5 * n * s.step_width_mm;
  const double y_lo = s.center_y_mm - 0.5 * s.length_mm, y_hi = s.center_y_mm + 0.5 * s.length_mm;
  const int bins = static_cast<int>(std::ceil(s.length_mm / s.bin_mm));

  StepGaugeResult r;
  r.steps.resize(n);
  std::vector<std::vector<double>> bin_sum(n, std::vector<double>(bins, 0.0));
  std::vector<std::vector<int>> bin_count(n, std::vector<int>(bins, 0));
  double sum_sq_all = 0;
  // Per scan line on a step: first and last y on the top surface (for the length).
  std::map<int, std::vector<LinePoint>> tops;  // per line: its points on a step's top

  for (const geometry::CloudPoint& p : cloud) {
    const double x = p.point_in_galvo.x(), y = p.point_in_galvo.y(), z = p.point_in_galvo.z();
    const int i = static_cast<int>(std::floor((x - x0) / s.step_width_mm));
    if (i < 0 || i >= n) continue;
    const double step_lo = x0 + i * s.step_width_mm, step_hi = step_lo + s.step_width_mm;
    const double nominal = s.base_z_mm + s.heights_mm[i];
    // Length: any point on this step's top, its x inside the step's margins.
    if (x > step_lo + s.edge_margin_mm && x < step_hi - s.edge_margin_mm &&
        z > s.base_z_mm + 0.5 * s.heights_mm[i]) {
      tops[p.line].push_back({x, y, z, p.intensity});
    }
    if (x <= step_lo + s.edge_margin_mm || x >= step_hi - s.edge_margin_mm) continue;
    if (y <= y_lo + s.edge_margin_mm || y >= y_hi - s.edge_margin_mm) continue;
    const double err = z - nominal;
    StepResult& st = r.steps[i];
    ++st.points;
    st.mean_error_mm += err;
    st.rms_error_mm += err * err;
    st.max_abs_error_mm = std::max(st.max_abs_error_mm, std::abs(err));
    const int b = std::clamp(static_cast<int>((y - y_lo) / s.bin_mm), 0, bins - 1);
    bin_sum[i][b] += err;
    ++bin_count[i][b];
    sum_sq_all += err * err;
    ++r.points;
    r.max_abs_error_mm = std::max(r.max_abs_error_mm, std::abs(err));
  }
  if (r.points == 0) {
    return InvalidArgument("no scan point fell on the step gauge's tops: check artifact "
                           "placement (center_mm) against the scanned x range");
  }
  r.rms_error_mm = std::sqrt(sum_sq_all / r.points);
  for (int i = 0; i < n; ++i) {
    StepResult& st = r.steps[i];
    st.nominal_mm = s.heights_mm[i];
    if (st.points > 0) {
      st.mean_error_mm /= st.points;
      st.rms_error_mm = std::sqrt(st.rms_error_mm / st.points);
    } else {
      st.mean_error_mm = st.rms_error_mm = st.max_abs_error_mm = std::nan("");
    }
    for (int b = 0; b < bins; ++b) {
      st.bin_y_mm.push_back(y_lo + (b + 0.5) * s.bin_mm);
      st.bin_mean_error_mm.push_back(bin_count[i][b] > 0 ? bin_sum[i][b] / bin_count[i][b]
                                                         : std::nan(""));
      if (bin_count[i][b] > 0) {
        r.max_abs_binned_error_mm =
            std::max(r.max_abs_binned_error_mm, std::abs(st.bin_mean_error_mm.back()));
      }
    }
  }
  // A line counts for the length only if it reached both ends of the top (within 2 mm).
  double sum = 0, sum_sq = 0;
  for (auto& [line, top] : tops) {
    const Extent e = TopExtent(&top);
    if (e.y_min > y_lo + 2.0 || e.y_max < y_hi - 2.0 || e.points < 2) continue;
    const double len = e.y_max - e.y_min;
    sum += len;
    sum_sq += len * len;
    ++r.length_lines;
  }
  if (r.length_lines > 0) {
    r.length_mm = sum / r.length_lines;
    r.length_std_mm = std::sqrt(std::max(0.0, sum_sq / r.length_lines - r.length_mm * r.length_mm));
  } else {
    r.length_mm = r.length_std_mm = std::nan("");
  }
  return r;
}

}  // namespace insitu::inspect
