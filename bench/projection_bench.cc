// Projection of a dense raster onto a large measured cloud: the focus height of every point of
// a 2000 x 2000 raster pattern over a 1 M point scan of the 40 x 40 mm arc part (galvo frame,
// mm), single-threaded, against a plain kd-tree k-nearest baseline measured in the same run.
//
// Target: HeightGrid build + projection of all 4 M raster points under 1 s on one core.
//
//   build/bin/projection_bench                  # both cases, then the summary
//   taskset -c 0 build/bin/projection_bench     # pinned to one core (all of it is single-threaded)
//
// BM_HeightGridProject/0 builds the grid from the cloud and samples the whole raster (heights;
// /1 adds the normals). BM_KdTreeKnnBaseline builds a FLANN kd-tree over the cloud's xy and
// averages the heights of the k = 8 nearest points of each raster point. That takes seconds for
// 4 M points, so it queries every 16th raster row (250 000 points) and extrapolates linearly to
// the full raster: build + 4 M x time per point. It also reports the largest height difference
// between the two on that subset where the grid gives a height (the baseline always answers,
// also beyond the scan, where the grid refuses), and each one's largest error against the
// analytic surface there: the mean of 8 neighbours is the height at their centroid, up to
// ~0.02 mm from the query, on slopes up to 1.
//
// Times are the fastest iteration: on a shared machine other processes only ever add time.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <flann/flann.hpp>

#include "insitu/geometry/height_grid.h"

namespace {

using insitu::geometry::Cloud;
using insitu::geometry::CloudPoint;
using insitu::geometry::HeightGrid;
using insitu::geometry::HeightGridOptions;
using insitu::geometry::Raster;
using insitu::geometry::RasterHeights;
using insitu::geometry::SurfaceMiss;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// The arc part (sim PartOptions defaults): a cylindrical crown, axis along y, 40 mm wide, 11.5 mm
// high at x = 0 and 3 mm at x = +-20 mm (radius 27.8 mm, slope up to 1.04).
constexpr double kHalfWidth = 20.0;
constexpr double kTop = 11.5;
constexpr double kSagitta = 11.5 - 3.0;
const double kRadius = (kHalfWidth * kHalfWidth + kSagitta * kSagitta) / (2.0 * kSagitta);
double ArcTop(double x) { return kTop - kRadius + std::sqrt(kRadius * kRadius - x * x); }

// 1000 scan lines 0.04 mm apart across x, 1000 points 0.04 mm apart along each: 1 M points.
// Lines scatter ~1 um in x (the light plane's tilt), points 5 um in y (stripe sub-pixel
// noise), heights 0.01 mm (speckle). Fixed seed.
constexpr int kLines = 1000;
constexpr int kPointsPerLine = 1000;
constexpr double kSpacing = 0.04;

const Cloud& TheCloud() {
  static const Cloud cloud = [] {
    Cloud c;
    c.reserve(static_cast<size_t>(kLines) * kPointsPerLine);
    std::mt19937 rng(42);
    std::normal_distribution<double> z_noise(0.0, 0.01);
    std::uniform_real_distribution<double> y_jitter(-0.005, 0.005);
    for (int l = 0; l < kLines; ++l) {
      const double x_line = (l - 0.5 * (kLines - 1)) * kSpacing;
      for (int k = 0; k < kPointsPerLine; ++k) {
        const double y = (k - 0.5 * (kPointsPerLine - 1)) * kSpacing + y_jitter(rng);
        const double x = x_line + 1e-3 * std::sin(0.37 * y);
        CloudPoint p;
        p.point_in_galvo = Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y),
                                           static_cast<float>(ArcTop(x) + z_noise(rng)));
        p.line = l;
        c.push_back(p);
      }
    }
    return c;
  }();
  return cloud;
}

// 2000 x 2000 points 0.02 mm apart over the whole part (the cloud spans +-19.98 mm).
Raster TheRaster() {
  Raster r;
  r.rows = r.cols = 2000;
  r.pitch_x_mm = r.pitch_y_mm = 0.02;
  r.x0_mm = r.y0_mm = -19.99;
  return r;
}
constexpr int kSubsetRowStep = 16;

// The grid's options: SurfaceOptions' radius, residual and point count, 0.05 mm cells.
HeightGridOptions GridOptions() { return HeightGridOptions{}; }

// Fastest HeightGrid build and projection (heights only) of this run, for the ratio.
struct GridTimes {
  double build_s = std::numeric_limits<double>::infinity();
  double project_s = std::numeric_limits<double>::infinity();
  double total_s = std::numeric_limits<double>::infinity();
};
GridTimes g_grid;

struct BaselineResult {
  double build_s = NAN;
  double per_point_s = NAN;
  double full_s = NAN;
  double max_disagreement_mm = NAN;
  double grid_max_error_mm = NAN;  // against the analytic surface, same points
  double baseline_max_error_mm = NAN;
  int64_t compared = 0;
  int64_t baseline_only = 0;
};
BaselineResult g_baseline;

// One build + projection; false (after SkipWithError) on failure.
bool GridOnce(benchmark::State* state, bool with_normals, RasterHeights* out, GridTimes* t) {
  const Clock::time_point t0 = Clock::now();
  auto grid = HeightGrid::Build(TheCloud(), GridOptions());
  const Clock::time_point t1 = Clock::now();
  if (!grid.ok()) {
    if (state) state->SkipWithError(grid.status().ToString().c_str());
    return false;
  }
  if (!grid->SampleRaster(TheRaster(), out, with_normals).ok()) {
    if (state) state->SkipWithError("SampleRaster failed");
    return false;
  }
  const Clock::time_point t2 = Clock::now();
  t->build_s = std::min(t->build_s, Seconds(t0, t1));
  t->project_s = std::min(t->project_s, Seconds(t1, t2));
  t->total_s = std::min(t->total_s, Seconds(t0, t2));
  return true;
}

void BM_HeightGridProject(benchmark::State& state) {
  const bool with_normals = state.range(0) != 0;
  TheCloud();  // generated outside the timing
  RasterHeights out;
  GridTimes t;
  for (auto _ : state) {
    if (!GridOnce(&state, with_normals, &out, &t)) return;
    benchmark::DoNotOptimize(out.z_mm.data());
  }
  if (!with_normals) g_grid = t;
  state.counters["build_ms"] = t.build_s * 1e3;
  state.counters["project_ms"] = t.project_s * 1e3;
  state.counters["total_ms"] = t.total_s * 1e3;
  state.counters["points"] = static_cast<double>(out.z_mm.size());
  state.counters["valid_pct"] = 100.0 * static_cast<double>(out.valid) / out.z_mm.size();
}
BENCHMARK(BM_HeightGridProject)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(5);

void BM_KdTreeKnnBaseline(benchmark::State& state) {
  constexpr int kK = 8;
  const Cloud& cloud = TheCloud();
  const Raster full = TheRaster();
  Raster subset = full;
  subset.rows = (full.rows + kSubsetRowStep - 1) / kSubsetRowStep;
  subset.pitch_y_mm = full.pitch_y_mm * kSubsetRowStep;
  const size_t n_queries = static_cast<size_t>(subset.rows) * subset.cols;
  std::vector<float> queries(2 * n_queries);
  for (int r = 0; r < subset.rows; ++r) {
    for (int c = 0; c < subset.cols; ++c) {
      const size_t q = static_cast<size_t>(r) * subset.cols + c;
      queries[2 * q] = static_cast<float>(subset.x0_mm + c * subset.pitch_x_mm);
      queries[2 * q + 1] = static_cast<float>(subset.y0_mm + r * subset.pitch_y_mm);
    }
  }
  std::vector<size_t> indices(n_queries * kK);
  std::vector<float> dists(n_queries * kK);
  std::vector<float> knn_z(n_queries);
  double best_build = std::numeric_limits<double>::infinity();
  double best_query = std::numeric_limits<double>::infinity();
  for (auto _ : state) {
    const Clock::time_point t0 = Clock::now();
    std::vector<float> xy(2 * cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) {
      xy[2 * i] = cloud[i].point_in_galvo.x();
      xy[2 * i + 1] = cloud[i].point_in_galvo.y();
    }
    flann::Index<flann::L2_Simple<float>> index(flann::Matrix<float>(xy.data(), cloud.size(), 2),
                                                flann::KDTreeSingleIndexParams(10));
    index.buildIndex();
    const Clock::time_point t1 = Clock::now();
    flann::Matrix<float> q(queries.data(), n_queries, 2);
    flann::Matrix<size_t> idx(indices.data(), n_queries, kK);
    flann::Matrix<float> d(dists.data(), n_queries, kK);
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
    params.cores = 1;
    index.knnSearch(q, idx, d, kK, params);
    for (size_t i = 0; i < n_queries; ++i) {
      double sum = 0.0;
      for (int k = 0; k < kK; ++k) sum += cloud[indices[i * kK + k]].point_in_galvo.z();
      knn_z[i] = static_cast<float>(sum / kK);
    }
    const Clock::time_point t2 = Clock::now();
    benchmark::DoNotOptimize(knn_z.data());
    best_build = std::min(best_build, Seconds(t0, t1));
    best_query = std::min(best_query, Seconds(t1, t2));
  }

  // The grid on the same subset, for the disagreement; and its full-raster time for the ratio,
  // measured here if BM_HeightGridProject/0 was filtered out.
  if (!std::isfinite(g_grid.total_s)) {
    RasterHeights scratch;
    if (!GridOnce(&state, false, &scratch, &g_grid)) return;
  }
  auto grid = HeightGrid::Build(cloud, GridOptions());
  RasterHeights on_subset;
  if (!grid.ok() || !grid->SampleRaster(subset, &on_subset).ok()) {
    state.SkipWithError("HeightGrid on the subset failed");
    return;
  }
  BaselineResult b;
  b.build_s = best_build;
  b.per_point_s = best_query / static_cast<double>(n_queries);
  b.full_s = best_build + b.per_point_s * full.rows * full.cols;
  b.max_disagreement_mm = b.grid_max_error_mm = b.baseline_max_error_mm = 0.0;
  for (size_t i = 0; i < n_queries; ++i) {
    if (on_subset.miss[i] != SurfaceMiss::kNone) {
      ++b.baseline_only;
      continue;
    }
    ++b.compared;
    const double truth = ArcTop(queries[2 * i]);
    b.max_disagreement_mm =
        std::max(b.max_disagreement_mm, std::abs(double{on_subset.z_mm[i]} - knn_z[i]));
    b.grid_max_error_mm = std::max(b.grid_max_error_mm, std::abs(on_subset.z_mm[i] - truth));
    b.baseline_max_error_mm = std::max(b.baseline_max_error_mm, std::abs(knn_z[i] - truth));
  }
  g_baseline = b;
  state.counters["build_ms"] = b.build_s * 1e3;
  state.counters["per_point_us"] = b.per_point_s * 1e6;
  state.counters["full_extrapolated_ms"] = b.full_s * 1e3;
  state.counters["grid_over_baseline"] = g_grid.total_s / b.full_s;
  state.counters["max_disagreement_um"] = b.max_disagreement_mm * 1e3;
  state.counters["grid_max_err_um"] = b.grid_max_error_mm * 1e3;
  state.counters["baseline_max_err_um"] = b.baseline_max_error_mm * 1e3;
  state.counters["compared"] = static_cast<double>(b.compared);
  state.counters["baseline_only"] = static_cast<double>(b.baseline_only);
}
BENCHMARK(BM_KdTreeKnnBaseline)->Unit(benchmark::kMillisecond)->Iterations(2);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  const Raster r = TheRaster();
  const double points = static_cast<double>(r.rows) * r.cols;
  std::printf("\nraster %d x %d onto %zu cloud points, one core, fastest iteration:\n", r.rows,
              r.cols, TheCloud().size());
  if (std::isfinite(g_grid.total_s)) {
    std::printf(
        "  HeightGrid: build %.1f ms + projection %.1f ms = %.1f ms (target < 1000 ms: %s)\n",
        g_grid.build_s * 1e3, g_grid.project_s * 1e3, g_grid.total_s * 1e3,
        g_grid.total_s < 1.0 ? "met" : "NOT met");
  }
  if (!std::isnan(g_baseline.full_s)) {
    std::printf(
        "  kd-tree 8-nearest baseline: build %.1f ms + %.3f us/point x %.0f = %.0f ms "
        "(extrapolated from every %dth row)\n",
        g_baseline.build_s * 1e3, g_baseline.per_point_s * 1e6, points, g_baseline.full_s * 1e3,
        kSubsetRowStep);
    std::printf("  ratio HeightGrid / baseline = %.4f (baseline / HeightGrid = %.1f)\n",
                g_grid.total_s / g_baseline.full_s, g_baseline.full_s / g_grid.total_s);
    std::printf(
        "  max |HeightGrid - baseline| = %.4f mm over %lld points; %lld more have a baseline "
        "height but none from the grid (beyond the scan's edge)\n",
        g_baseline.max_disagreement_mm, static_cast<long long>(g_baseline.compared),
        static_cast<long long>(g_baseline.baseline_only));
    std::printf(
        "  max error against the analytic surface there: HeightGrid %.4f mm, baseline %.4f mm\n",
        g_baseline.grid_max_error_mm, g_baseline.baseline_max_error_mm);
  }
  benchmark::Shutdown();
  return 0;
}
