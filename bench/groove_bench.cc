// Groove profile processing (seed 002, inspect/groove.h) on one core: outliers, levelling and the
// tanh template's Levenberg-Marquardt fit for 1000 profiles of 201 points (a groove 0.5 mm wide
// and 0.1 mm deep on a tilted surface, 1 um noise, a spike and a short occlusion each), against
// a baseline measured in the same run: a least-squares line through every valid point of the
// same profiles (one pass over the data, the least any processing does). Line profilers run at
// 2-10 kHz; the target is >= 10,000 profiles/s.
//   build/bin/groove_bench
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "insitu/inspect/groove.h"

namespace {

using insitu::inspect::FitGroove;
using insitu::inspect::GrooveOptions;
using insitu::inspect::Profile;

const std::vector<Profile>& Profiles() {
  static const std::vector<Profile> profiles = [] {
    std::vector<Profile> out;
    std::mt19937_64 rng(7);
    std::normal_distribution<double> noise(0.0, 0.001);
    std::uniform_real_distribution<double> centre(-0.1, 0.1), slope(-0.05, 0.05);
    for (int k = 0; k < 1000; ++k) {
      Profile p;
      p.x_start_mm = -1.0;
      p.dx_mm = 0.01;
      const double c = centre(rng), s = slope(rng), a = 20.0, w = 0.5;
      const double d = 0.1 / std::tanh(0.25 * a * w);
      for (int i = 0; i <= 200; ++i) {
        const double x = p.x_start_mm + p.dx_mm * i, u = x - c;
        const double groove =
            -0.5 * d * (std::tanh(a * (u - 0.25 * w)) - std::tanh(a * (u + 0.25 * w)));
        p.z_mm.push_back(static_cast<float>(2.0 + s * x - groove + noise(rng)));
      }
      p.z_mm[30 + k % 100] += 0.05f;
      for (int i = 0; i < 4; ++i) p.z_mm[150 + i] = NAN;
      out.push_back(std::move(p));
    }
    return out;
  }();
  return profiles;
}

void BM_LineBaseline(benchmark::State& state) {
  const std::vector<Profile>& profiles = Profiles();
  for (auto _ : state) {
    for (const Profile& p : profiles) {
      double sx = 0, sz = 0, sxx = 0, sxz = 0, n = 0;
      for (size_t i = 0; i < p.z_mm.size(); ++i) {
        const double z = p.z_mm[i];
        if (!std::isfinite(z)) continue;
        const double x = p.x_start_mm + p.dx_mm * static_cast<double>(i);
        sx += x;
        sz += z;
        sxx += x * x;
        sxz += x * z;
        n += 1;
      }
      const double k = (n * sxz - sx * sz) / (n * sxx - sx * sx);
      benchmark::DoNotOptimize(k);
    }
  }
  state.counters["profiles_per_s"] = benchmark::Counter(
      static_cast<double>(profiles.size()) * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_LineBaseline)->Unit(benchmark::kMicrosecond)->Repetitions(3);

void BM_FitGroove(benchmark::State& state) {
  const std::vector<Profile>& profiles = Profiles();
  const GrooveOptions options;
  int failed = 0;
  for (auto _ : state) {
    for (const Profile& p : profiles) {
      const auto g = FitGroove(p, options);
      failed += g.ok ? 0 : 1;
      benchmark::DoNotOptimize(g);
    }
  }
  if (failed > 0) state.SkipWithError("a profile failed to fit");
  state.counters["profiles_per_s"] = benchmark::Counter(
      static_cast<double>(profiles.size()) * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_FitGroove)->Unit(benchmark::kMillisecond)->Repetitions(3);

// Console output as usual, plus the fastest real time per iteration of each benchmark.
class FastestReporter : public benchmark::ConsoleReporter {
 public:
  FastestReporter() : ConsoleReporter(isatty(fileno(stdout)) ? OO_ColorTabular : OO_Tabular) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) {
      if (run.error_occurred || run.iterations == 0 || run.run_type != Run::RT_Iteration) continue;
      const double t = run.real_accumulated_time / static_cast<double>(run.iterations);
      auto [it, inserted] = fastest_.emplace(run.run_name.function_name, t);
      if (!inserted) it->second = std::min(it->second, t);
    }
    ConsoleReporter::ReportRuns(runs);
  }
  double Seconds(const std::string& name) const {
    auto it = fastest_.find(name);
    return it == fastest_.end() ? NAN : it->second;
  }

 private:
  std::map<std::string, double> fastest_;
};

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  FastestReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double n = static_cast<double>(Profiles().size());
  const double line = reporter.Seconds("BM_LineBaseline"), fit = reporter.Seconds("BM_FitGroove");
  std::printf("\nper profile (fastest of the repetitions): line %.2f us, groove %.1f us\n",
              1e6 * line / n, 1e6 * fit / n);
  std::printf("groove profiles/s on one core = %.0f (target >= 10000)\n", n / fit);
  std::printf("groove/line = %.1f\n", fit / line);
  benchmark::Shutdown();
  return 0;
}
