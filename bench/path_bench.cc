// Path optimisation (seed 004) of the dense 1181-point glyph outline of the test
// (tests/pattern/dense_outline.h) at the seed's two magnifications, 36x (1 px = 0.06 mm) and
// 72x (0.12 mm), within a total error of 2 um (PathOptOptions::ForErrorBudget).
//
// Baseline, measured in the same run: the seed's unoptimised output, every input point scaled
// to a mark (BM_RawMarks). Counters: marks (emitted mark points), mark_ratio (marks / 1181),
// max_err_um (measured Hausdorff distance between the scaled input and the marks). After the
// runs the time ratios against the baseline are printed.
//
//   build/bin/path_bench
//   build/bin/path_bench --benchmark_filter='Raw|Optimise'   # the ratios only
//
// BM_OptimisePolyline includes the error measurement of the summary; BM_FitAndInterpolate is
// the optimisation alone (what a marking job needs).
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <unistd.h>

#include <benchmark/benchmark.h>

#include "insitu/pattern/path_opt.h"
#include "pattern/dense_outline.h"

namespace {

using insitu::pattern::OptimisedMarks;
using insitu::pattern::PathOptOptions;
using insitu::pattern::Polyline;

constexpr double kMaxErrorMm = 0.002;

const Polyline& Glyph() {
  static const Polyline glyph = insitu::pattern::testing::DenseGlyphOutline();
  return glyph;
}

// Benchmark arguments: magnification (36 or 72), placement (0 on the curve, 2 tolerance band).
PathOptOptions Options(const benchmark::State& state) {
  PathOptOptions o = PathOptOptions::ForErrorBudget(state.range(0) / 600.0, kMaxErrorMm);
  o.placement = static_cast<PathOptOptions::Placement>(state.range(1));
  return o;
}

void BM_RawMarks(benchmark::State& state) {
  const Polyline& glyph = Glyph();
  const double scale = state.range(0) / 600.0;
  std::vector<Eigen::Vector2d> marks;
  for (auto _ : state) {
    marks.clear();
    for (const Eigen::Vector2d& p : glyph.points) marks.push_back(scale * p);
    benchmark::DoNotOptimize(marks.data());
    benchmark::ClobberMemory();
  }
  state.counters["marks"] = static_cast<double>(marks.size());
  state.counters["mark_ratio"] = 1.0;
}
BENCHMARK(BM_RawMarks)->Args({36, 0})->Unit(benchmark::kMicrosecond);

void BM_OptimisePolyline(benchmark::State& state) {
  const PathOptOptions o = Options(state);
  insitu::Result<OptimisedMarks> out = insitu::InvalidArgument("not run");
  for (auto _ : state) {
    out = insitu::pattern::OptimisePolyline(Glyph(), o);
    benchmark::DoNotOptimize(out);
  }
  if (!out.ok()) {
    state.SkipWithError(out.status().ToString().c_str());
    return;
  }
  state.counters["marks"] = out->summary.mark_points;
  state.counters["mark_ratio"] =
      static_cast<double>(out->summary.mark_points) / out->summary.input_points;
  state.counters["max_err_um"] = out->summary.max_error_mm * 1e3;
  state.counters["control_points"] = out->summary.control_points;
}
BENCHMARK(BM_OptimisePolyline)
    ->ArgNames({"mag", "placement"})
    ->Args({36, 0})
    ->Args({72, 0})
    ->Args({36, 2})
    ->Args({72, 2})
    ->Unit(benchmark::kMillisecond);

void BM_FitAndInterpolate(benchmark::State& state) {
  const PathOptOptions o = Options(state);
  size_t marks = 0;
  for (auto _ : state) {
    auto path = insitu::pattern::FitPath(Glyph(), o);
    if (!path.ok()) {
      state.SkipWithError(path.status().ToString().c_str());
      return;
    }
    const Polyline m = insitu::pattern::Interpolate(*path, o);
    marks = m.points.size();
    benchmark::DoNotOptimize(m.points.data());
  }
  state.counters["marks"] = static_cast<double>(marks);
}
BENCHMARK(BM_FitAndInterpolate)
    ->ArgNames({"mag", "placement"})
    ->Args({36, 0})
    ->Args({72, 2})
    ->Unit(benchmark::kMillisecond);

// Console output as usual, plus the real time per iteration of every run, for the ratios.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  RatioReporter() : ConsoleReporter(isatty(fileno(stdout)) ? OO_ColorTabular : OO_Tabular) {}

  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) {
      if (run.error_occurred || run.iterations == 0) continue;
      seconds_[run.benchmark_name()] =
          run.real_accumulated_time / static_cast<double>(run.iterations);
      if (auto it = run.counters.find("marks"); it != run.counters.end()) {
        marks_[run.benchmark_name()] = it->second.value;
      }
    }
    ConsoleReporter::ReportRuns(runs);
  }

  // NaN when the benchmark did not run (filtered out).
  double Seconds(const std::string& name) const {
    auto it = seconds_.find(name);
    return it == seconds_.end() ? NAN : it->second;
  }
  double Marks(const std::string& name) const {
    auto it = marks_.find(name);
    return it == marks_.end() ? NAN : it->second;
  }

 private:
  std::map<std::string, double> seconds_;
  std::map<std::string, double> marks_;
};

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double raw = reporter.Seconds("BM_RawMarks/36/0");
  std::printf(
      "\n1181-point outline, total error %.0f um; seed 004 Table 1: 207 marks at 36x, "
      "288 at 72x (1181 raw)\n",
      kMaxErrorMm * 1e3);
  std::printf("  %-44s %9s %8s %12s\n", "", "time", "marks", "time / raw");
  std::printf("  %-44s %6.1f us %8.0f %12s\n", "BM_RawMarks/36/0", raw * 1e6,
              reporter.Marks("BM_RawMarks/36/0"), "1");
  for (const char* name :
       {"BM_OptimisePolyline/mag:36/placement:0", "BM_OptimisePolyline/mag:72/placement:0",
        "BM_OptimisePolyline/mag:36/placement:2", "BM_OptimisePolyline/mag:72/placement:2",
        "BM_FitAndInterpolate/mag:36/placement:0", "BM_FitAndInterpolate/mag:72/placement:2"}) {
    const double t = reporter.Seconds(name);
    std::printf("  %-44s %6.2f ms %8.0f %12.0f\n", name, t * 1e3, reporter.Marks(name), t / raw);
  }
  benchmark::Shutdown();
  return 0;
}
