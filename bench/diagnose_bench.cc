// insitu diagnose on a 1000-point field (32 x 32 grid over +-50 mm, two-mirror pincushion with
// its centre off the origin, a rotation and 3 um noise), against the least work any diagnosis
// must do in the same run: one joint fit of the true model. And on a board's whole correction
// table (65 x 65 = 4,225 nodes over a 110 mm lens, from the simulator's optics: f-theta
// distortion, tilted axes, zero offsets, gain errors; 1 um noise), against one fit of the
// physical head alone; target < 5 s.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "insitu/fit/diagnose.h"
#include "insitu/fit/effects.h"
#include "insitu/fit/model_fit.h"
#include "insitu/optics/scan_head.h"

namespace {

using insitu::fit::FieldData;

FieldData Field() {
  FieldData d;
  d.origin = "<bench>";
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g(0.0, 0.003);
  const auto pin = insitu::fit::MakeEffect("mirror_separation");
  const auto rot = insitu::fit::MakeEffect("rotation");
  const double pin_q[3] = {1.5e-6, 6.0, -3.0}, rot_q[1] = {8e-4};
  for (int j = 0; j < 32; ++j) {
    for (int i = 0; i < 32; ++i) {
      insitu::fit::FieldPoint p;
      p.cmd = {-50.0 + 100.0 * i / 31, -50.0 + 100.0 * j / 31};
      Eigen::Vector2d uv = p.cmd;
      pin->Apply(p, pin_q, &uv);
      rot->Apply(p, rot_q, &uv);
      p.meas = uv + Eigen::Vector2d(g(rng), g(rng));
      d.points.push_back(p);
    }
  }
  return d;
}

const FieldData& Data() {
  static const FieldData d = Field();
  return d;
}

void BM_Diagnose(benchmark::State& state) {
  for (auto _ : state) {
    auto d = insitu::fit::Diagnose(Data());
    if (!d.ok() || d->cause.size() != 2) state.SkipWithError("diagnosis failed or wrong cause");
    benchmark::DoNotOptimize(d);
  }
  state.counters["points"] = static_cast<double>(Data().points.size());
}
BENCHMARK(BM_Diagnose)->Unit(benchmark::kMillisecond)->Iterations(5);

void BM_OneJointFit(benchmark::State& state) {
  const auto pin = insitu::fit::MakeEffect("mirror_separation");
  const auto rot = insitu::fit::MakeEffect("rotation");
  for (auto _ : state) {
    auto f = insitu::fit::FitEffects(Data(), {pin.get(), rot.get()});
    benchmark::DoNotOptimize(f);
  }
}
BENCHMARK(BM_OneJointFit)->Unit(benchmark::kMillisecond)->Iterations(20);

// The head without its table: commanded on a 65 x 65 grid, landing where the head puts it.
FieldData Table() {
  FieldData d;
  d.origin = "<bench table>";
  insitu::optics::HeadGeometry g;
  g.focal_length_mm = 160.0;
  g.ftheta_c3 = 0.04;
  g.ftheta_c5 = -0.1;
  g.x_axis_tilt_mrad = 1.5;
  g.y_axis_tilt_mrad = -0.8;
  const insitu::optics::ScanOptics optics(g);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.001);
  for (int j = 0; j < 65; ++j) {
    for (int i = 0; i < 65; ++i) {
      insitu::fit::FieldPoint p;
      p.cmd = {-55.0 + 110.0 * i / 64, -55.0 + 110.0 * j / 64};
      insitu::optics::MirrorAngles a;
      a.x_rad = 1.004 * p.cmd.x() / g.focal_length_mm + 0.6e-3;
      a.y_rad = 0.997 * p.cmd.y() / g.focal_length_mm - 0.4e-3;
      const Eigen::Vector3d s = optics.Trace(a).focal_point_in_world;
      p.meas = {s.x() + noise(rng), s.y() + noise(rng)};
      d.points.push_back(p);
    }
  }
  return d;
}

const FieldData& TableData() {
  static const FieldData d = Table();
  return d;
}

void BM_DiagnoseTable(benchmark::State& state) {
  for (auto _ : state) {
    auto d = insitu::fit::Diagnose(TableData());
    if (!d.ok() || d->cause.empty() || d->cause[0] != "head_geometry") {
      state.SkipWithError("diagnosis failed or did not name the head");
    }
    benchmark::DoNotOptimize(d);
  }
  state.counters["points"] = static_cast<double>(TableData().points.size());
}
BENCHMARK(BM_DiagnoseTable)->Unit(benchmark::kMillisecond)->Iterations(2);

void BM_OneHeadFit(benchmark::State& state) {
  const auto head = insitu::fit::MakeEffect("head_geometry");
  for (auto _ : state) {
    auto f = insitu::fit::FitEffects(TableData(), {head.get()});
    benchmark::DoNotOptimize(f);
  }
}
BENCHMARK(BM_OneHeadFit)->Unit(benchmark::kMillisecond)->Iterations(3);

class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      const double ms = r.GetAdjustedRealTime();  // in the benchmark's unit (ms)
      if (r.benchmark_name().find("BM_Diagnose/") == 0 || r.benchmark_name() == "BM_Diagnose") {
        diagnose_ms_ = ms;
      }
      if (r.benchmark_name().find("BM_OneJointFit") == 0) fit_ms_ = ms;
      if (r.benchmark_name().find("BM_DiagnoseTable") == 0) table_ms_ = ms;
      if (r.benchmark_name().find("BM_OneHeadFit") == 0) head_fit_ms_ = ms;
    }
    ConsoleReporter::ReportRuns(runs);
  }
  double diagnose_ms_ = NAN, fit_ms_ = NAN, table_ms_ = NAN, head_fit_ms_ = NAN;
};

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  std::printf(
      "\n1024-point diagnosis: %.0f ms (target < 2000 ms: %s); one joint fit of the true "
      "model %.2f ms; diagnosis / fit = %.0f\n",
      reporter.diagnose_ms_, reporter.diagnose_ms_ < 2000 ? "met" : "NOT met", reporter.fit_ms_,
      reporter.diagnose_ms_ / reporter.fit_ms_);
  std::printf(
      "4225-node table diagnosis: %.0f ms (target < 5000 ms: %s); one fit of the physical head "
      "%.0f ms; table diagnosis / head fit = %.1f\n",
      reporter.table_ms_, reporter.table_ms_ < 5000 ? "met" : "NOT met", reporter.head_fit_ms_,
      reporter.table_ms_ / reporter.head_fit_ms_);
  return 0;
}
