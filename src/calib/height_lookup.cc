#include "insitu/calib/height_lookup.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/Dense>

#include "insitu/core/robust.h"

namespace insitu::calib {
namespace {

constexpr int kDegree = 5;

// Cubic (4-point Lagrange) interpolation of y(x) at `at` from nodes sorted by x; allows
// extrapolation up to half of the outer node spacing. Fewer than 4 nodes: lower order.
std::optional<double> Interpolate(const std::vector<double>& x, const std::vector<double>& y,
                                  double at) {
  const size_t n = x.size();
  if (n < 2) return std::nullopt;
  if (at < x.front() - 0.5 * (x[1] - x[0]) || at > x.back() + 0.5 * (x[n - 1] - x[n - 2])) {
    return std::nullopt;
  }
  size_t k = static_cast<size_t>(std::upper_bound(x.begin(), x.end(), at) - x.begin());
  const size_t m = std::min<size_t>(4, n);
  size_t start = k >= 2 ? k - 2 : 0;
  start = std::min(start, n - m);
  double sum = 0.0;
  for (size_t a = start; a < start + m; ++a) {
    double w = 1.0;
    for (size_t b = start; b < start + m; ++b) {
      if (b != a) w *= (at - x[b]) / (x[a] - x[b]);
    }
    sum += w * y[a];
  }
  return sum;
}

}  // namespace

double StripeCurve::Eval(double u) const {
  const double t = (2.0 * u - u_min - u_max) / (u_max - u_min);
  double v = 0.0;
  for (size_t k = coeffs.size(); k-- > 0;) v = v * t + coeffs[k];
  return v;
}

HeightLookup HeightLookup::Build(const std::vector<HeightObservation>& obs,
                                 HeightLookupSummary* summary) {
  HeightLookup lookup;
  *summary = HeightLookupSummary{};
  std::map<std::pair<double, double>, const HeightObservation*> grid;
  std::vector<double> xs, zs;
  for (const HeightObservation& o : obs) {
    grid[{o.line_x_mm, o.stage_z_mm}] = &o;
    xs.push_back(o.line_x_mm);
    zs.push_back(o.stage_z_mm);
  }
  auto unique_sorted = [](std::vector<double>* v) {
    std::sort(v->begin(), v->end());
    v->erase(std::unique(v->begin(), v->end()), v->end());
  };
  unique_sorted(&xs);
  unique_sorted(&zs);
  if (xs.size() < 4 || zs.size() < 4) {
    summary->message = "height calibration needs at least 4 line offsets and 4 stage heights, got " +
                       std::to_string(xs.size()) + " and " + std::to_string(zs.size());
    return lookup;
  }
  if (grid.size() != xs.size() * zs.size()) {
    summary->message = "height calibration grid is incomplete: " + std::to_string(grid.size()) +
                       " of " + std::to_string(xs.size() * zs.size()) + " (offset, height) frames";
    return lookup;
  }
  double sum_sq = 0.0;
  size_t count = 0;
  for (double x : xs) {
    for (double z : zs) {
      const HeightObservation& o = *grid[{x, z}];
      if (o.centres.size() < 50) {
        summary->message = "line at x = " + std::to_string(x) + " mm, height " +
                           std::to_string(z) + " mm: only " + std::to_string(o.centres.size()) +
                           " stripe centres (is the plate clear and lit?)";
        return HeightLookup{};
      }
      StripeCurve c;
      c.u_min = c.u_max = o.centres.front().x();
      for (const Eigen::Vector2d& p : o.centres) {
        c.u_min = std::min(c.u_min, p.x());
        c.u_max = std::max(c.u_max, p.x());
      }
      // Least squares, then again without the centres far off the curve (a few columns of a
      // reflection or of the line's turning ends would otherwise bend it): off means beyond
      // 5 robust sigmas (1.4826 MAD of the residuals) and beyond 1 px.
      std::vector<char> keep(o.centres.size(), 1);
      std::vector<double> residual(o.centres.size());
      for (int pass = 0; pass < 3; ++pass) {
        const size_t n = std::count(keep.begin(), keep.end(), 1);
        Eigen::MatrixXd a(n, kDegree + 1);
        Eigen::VectorXd b(n);
        for (size_t r = 0, row = 0; r < o.centres.size(); ++r) {
          if (!keep[r]) continue;
          const double t = (2.0 * o.centres[r].x() - c.u_min - c.u_max) / (c.u_max - c.u_min);
          double tk = 1.0;
          for (int k = 0; k <= kDegree; ++k, tk *= t) a(row, k) = tk;
          b(row++) = o.centres[r].y();
        }
        const Eigen::VectorXd coeffs = a.colPivHouseholderQr().solve(b);
        c.coeffs.assign(coeffs.data(), coeffs.data() + coeffs.size());
        std::vector<double> abs_kept;
        for (size_t r = 0; r < o.centres.size(); ++r) {
          residual[r] = c.Eval(o.centres[r].x()) - o.centres[r].y();
          if (keep[r]) abs_kept.push_back(std::abs(residual[r]));
        }
        const double limit = std::max(1.0, 5.0 * kMadToSigma * MedianInPlace(abs_kept));
        bool changed = false;
        for (size_t r = 0; r < o.centres.size(); ++r) {
          const char k = std::abs(residual[r]) <= limit;
          changed |= k != keep[r];
          keep[r] = k;
        }
        if (!changed) break;
      }
      for (size_t r = 0; r < o.centres.size(); ++r) {
        if (!keep[r]) {
          ++summary->outliers;
          continue;
        }
        const double e = residual[r];
        sum_sq += e * e;
        summary->fit_max_px = std::max(summary->fit_max_px, std::abs(e));
        ++count;
      }
      lookup.curves_.push_back(std::move(c));
    }
  }
  lookup.xs_ = xs;
  lookup.zs_ = zs;
  summary->fit_rms_px = std::sqrt(sum_sq / std::max<size_t>(1, count));
  summary->ok = true;
  summary->message = "ok";
  return lookup;
}

std::optional<double> HeightLookup::Height(double line_x_mm, double u, double v) const {
  if (xs_.size() < 2) return std::nullopt;
  // First the stripe curves of a line at line_x_mm, one per calibrated height, interpolated
  // across the neighbouring offsets (cubic in x); then the height at which that line's stripe
  // passes through v at this column (cubic in v). Both stay inside the calibrated domain.
  const double spacing = (xs_.back() - xs_.front()) / static_cast<double>(xs_.size() - 1);
  // Scratch reused by each thread: a scan asks once per stripe point, and allocating these
  // per call took a fifth of the scan's per-frame time (perf on bench/scan_pipeline_bench).
  thread_local std::vector<double> vs, nx, nv, sv, sz;
  thread_local std::vector<size_t> order;
  vs.resize(zs_.size());
  for (size_t j = 0; j < zs_.size(); ++j) {
    nx.clear();
    nv.clear();
    for (size_t i = 0; i < xs_.size(); ++i) {
      if (std::abs(xs_[i] - line_x_mm) > 2.01 * spacing) continue;
      const StripeCurve& c = curves_[i * zs_.size() + j];
      if (u < c.u_min || u > c.u_max) return std::nullopt;
      nx.push_back(xs_[i]);
      nv.push_back(c.Eval(u));
    }
    const auto vj = Interpolate(nx, nv, line_x_mm);
    if (!vj) return std::nullopt;
    vs[j] = *vj;
  }
  // v moves monotonically with height; interpolate z(v) with v as the abscissa.
  order.resize(zs_.size());
  for (size_t j = 0; j < order.size(); ++j) order[j] = j;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return vs[a] < vs[b]; });
  sv.clear();
  sz.clear();
  for (size_t j : order) {
    sv.push_back(vs[j]);
    sz.push_back(zs_[j]);
  }
  return Interpolate(sv, sz, v);
}

Result<HeightLookup> HeightLookup::FromParts(std::vector<double> xs, std::vector<double> zs,
                                             std::vector<StripeCurve> curves) {
  if (xs.size() < 2 || zs.size() < 2) return InvalidArgument("height_lookup needs >= 2 offsets and heights");
  if (!std::is_sorted(xs.begin(), xs.end()) || !std::is_sorted(zs.begin(), zs.end())) {
    return InvalidArgument("height_lookup line_x_mm and stage_z_mm must be increasing");
  }
  if (curves.size() != xs.size() * zs.size()) {
    return InvalidArgument("height_lookup has " + std::to_string(curves.size()) +
                           " curves, expected line_x_mm x stage_z_mm = " +
                           std::to_string(xs.size() * zs.size()));
  }
  for (const StripeCurve& c : curves) {
    if (!(c.u_max > c.u_min) || c.coeffs.empty()) {
      return InvalidArgument("height_lookup curve with an empty column range or no coefficients");
    }
  }
  HeightLookup l;
  l.xs_ = std::move(xs);
  l.zs_ = std::move(zs);
  l.curves_ = std::move(curves);
  return l;
}

}  // namespace insitu::calib
