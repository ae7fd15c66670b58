// The scan's whole per-frame path, on frames the simulator renders for the default cell as the
// scan job sees them: the step gauge and the arc, and the shop floor's bright gauge and glossy
// arc, 8- and 12-bit, with the camera's noise and
// speckle, the stripe running the way the cell's geometry gives it. Each frame goes through
// job::FrameProcessor, the code the scan job runs: stripe centres, undistortion, the line's
// light plane, the height lookup (method 2), appended to the cloud. A copy of the same frame is
// timed in the same run as the baseline.
//
//   build/bin/scan_pipeline_bench
//
// Every benchmark runs 5 repetitions; the ratios use the fastest of each (on a shared machine
// other processes only ever add time). The last line printed is the worst case's
// `pipeline/copy = X` over the default cell's scenes (target <= 4); the line before it the same
// over the shop floor's scenes (bright, glossy: target <= 8).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "insitu/calib/calibration.h"
#include "insitu/core/config.h"
#include "insitu/job/scan.h"
#include "insitu/sim/world.h"
#include "insitu/sim/world_config.h"

namespace {

using insitu::Frame;
using insitu::calib::CalibrationSet;
using insitu::job::FrameProcessor;
using insitu::job::ScanOptions;
using insitu::job::ScanOutput;

constexpr int kLines = 15;  // frames per case, across the scan: the part and the plate beside it

// The shipped step-gauge scan's settings (config/jobs/scan_step_gauge.yaml), method 2.
ScanOptions Options() {
  ScanOptions o;
  o.x_start_mm = -14.0;  // the shipped scan's lines: 4 mm of plate on each side of the gauge
  o.x_end_mm = 14.0;
  o.line_spacing_mm = 28.0 / (kLines - 1);
  o.y_start_mm = -50.0;
  o.y_end_mm = 50.0;
  o.method = 2;
  return o;
}

insitu::vision::StripeOptions Stripe() {
  insitu::vision::StripeOptions s;
  s.threshold_ratio = 0.5;
  return s;
}

// The as-designed calibration, with a height lookup built from its own geometry: the stripe
// curves of lines at x = -20..20 mm on planes z = -15..15 mm, projected through the camera. The
// lookup's cost per point does not depend on where its curves come from.
CalibrationSet Calibration() {
  auto cal = insitu::calib::LoadCalibration(std::string(INSITU_SOURCE_DIR) +
                                            "/calib/as_designed.yaml");
  if (!cal.ok()) {
    std::fprintf(stderr, "%s\n", cal.status().ToString().c_str());
    std::exit(1);
  }
  std::vector<insitu::calib::HeightObservation> obs;
  for (double x = -20.0; x <= 20.0; x += 5.0) {
    for (double z = -15.0; z <= 15.0; z += 5.0) {
      insitu::calib::HeightObservation o{x, z, {}};
      for (double y = -50.0; y <= 50.0; y += 0.5) {
        const Eigen::Vector3d p = cal->galvo.camera_from_galvo * Eigen::Vector3d(x, y, z);
        const Eigen::Vector2d px = cal->camera.Project(p);
        if (px.x() >= 0 && px.y() >= 0 && px.x() < cal->camera.width_px &&
            px.y() < cal->camera.height_px) {
          o.centres.push_back(px);
        }
      }
      obs.push_back(std::move(o));
    }
  }
  insitu::calib::HeightLookupSummary summary;
  cal->height_lookup = insitu::calib::HeightLookup::Build(obs, &summary);
  if (!summary.ok) {
    std::fprintf(stderr, "height lookup: %s\n", summary.message.c_str());
    std::exit(1);
  }
  return *cal;
}

struct Case {
  std::vector<Frame> frames;
  CalibrationSet calibration;
};

// The scenes: the default cell's step gauge and arc, then the shop floor's: the gauge under a
// lamp beside the cell with a white label on the plate beside it (bright), and a glossy arc
// (glints, and the mirrored line on the plate).
const char* kScenes[] = {"step_gauge", "arc", "bright step_gauge", "glossy arc"};
constexpr int kSceneCount = 4;
bool ShopFloor(int scene) { return scene >= 2; }

// Frames of the default cell's world with scene `scene` at `bit_depth`, one per line.
const Case& Frames(int scene, int bit_depth) {
  const std::string name = kScenes[scene];
  const std::string part = name.substr(name.find(' ') + 1);
  static std::map<std::string, Case> cases;
  const std::string key = name + std::to_string(bit_depth);
  auto it = cases.find(key);
  if (it != cases.end()) return it->second;
  auto doc = insitu::ConfigNode::LoadFile(std::string(INSITU_SOURCE_DIR) +
                                          "/config/worlds/default.yaml");
  insitu::sim::WorldOptions w;
  insitu::ConfigReader r(*doc);
  insitu::sim::ReadWorld(r, &w);
  if (!r.Finish().ok()) std::exit(1);
  w.part.kind = part;
  w.camera.bit_depth = bit_depth;
  if (name == "bright step_gauge") {
    w.light.lamp_position_mm = {0.0, 250.0, 150.0};
    w.light.lamp_lux = 1500.0;
    w.stage.labels = {{24.0, 0.0, 8.0, 80.0, 0.85}};
  } else if (name == "glossy arc") {
    w.part.albedo = 0.3;
    w.part.specular = 0.5;
  }
  insitu::sim::SimWorld world(w);
  Case c;
  c.calibration = Calibration();
  const ScanOptions o = Options();
  (void)world.SetExposure(o.exposure_ms * 1e3);
  for (int i = 0; i < kLines; ++i) {
    const double x = o.line_x(i);
    (void)world.StartPointerLine({x, o.y_start_mm, 0.0}, {x, o.y_end_mm, 0.0}, o.speed_mm_per_s);
    auto frame = world.Grab();
    if (!frame.ok()) std::exit(1);
    c.frames.push_back(std::move(*frame));
  }
  world.StopPointer();
  return cases.emplace(key, std::move(c)).first->second;
}

void BM_FrameCopy(benchmark::State& state) {
  const Case& c = Frames(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  std::vector<uint8_t> copy(c.frames[0].bytes.size());
  size_t k = 0;
  for (auto _ : state) {
    const Frame& f = c.frames[k++ % c.frames.size()];
    std::memcpy(copy.data(), f.bytes.data(), f.bytes.size());
    benchmark::DoNotOptimize(copy.data());
    benchmark::ClobberMemory();
  }
}

void BM_Pipeline(benchmark::State& state) {
  const Case& c = Frames(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  auto processor = FrameProcessor::Create(Options(), Stripe(), c.calibration);
  if (!processor.ok()) {
    state.SkipWithError(processor.status().ToString().c_str());
    return;
  }
  ScanOutput out;
  size_t k = 0;
  int64_t points = 0;
  double extract_ms = 0.0;  // over every frame processed (a scan's worth at a time in `out`)
  for (auto _ : state) {
    const size_t i = k++ % c.frames.size();
    if (i == 0) {  // the cloud of one scan at a time, as the job keeps it
      points += out.cloud.size();
      extract_ms += out.stats.extract_time_ms;
      out = ScanOutput();
    }
    const insitu::Status s = (*processor)->Process(c.frames[i], static_cast<int>(i), &out);
    if (!s.ok()) {
      state.SkipWithError(s.ToString().c_str());
      return;
    }
  }
  points += out.cloud.size();
  state.counters["points_per_frame"] =
      benchmark::Counter(static_cast<double>(points) / static_cast<double>(k));
  extract_ms += out.stats.extract_time_ms;
  state.counters["extract_ms"] =
      benchmark::Counter(extract_ms / static_cast<double>(std::max<size_t>(1, k)));
}

void Cases(benchmark::internal::Benchmark* b) {
  for (int scene = 0; scene < kSceneCount; ++scene) {
    for (int bits : {8, 12}) b->Args({scene, bits});
  }
  b->Repetitions(5)->ReportAggregatesOnly(false)->Unit(benchmark::kMillisecond);
}

BENCHMARK(BM_FrameCopy)->Apply(Cases);
BENCHMARK(BM_Pipeline)->Apply(Cases);

// Keeps the fastest repetition of each run name.
class MinReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& r : runs) {
      if (r.run_type != Run::RT_Iteration || r.error_occurred) continue;
      const double t = r.GetAdjustedRealTime();
      auto [it, fresh] = fastest.emplace(r.run_name.str(), t);
      if (!fresh) it->second = std::min(it->second, t);
    }
  }
  std::map<std::string, double> fastest;
};

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  MinReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  double worst = 0.0, worst_shop = 0.0;
  for (const auto& [name, t] : reporter.fastest) {
    if (name.rfind("BM_Pipeline/", 0) != 0) continue;
    const std::string args = name.substr(std::strlen("BM_Pipeline/"));
    const auto copy = reporter.fastest.find("BM_FrameCopy/" + args);
    if (copy == reporter.fastest.end()) continue;
    const int scene = std::atoi(args.c_str());
    const double ratio = t / copy->second;
    std::printf("%s (%s): pipeline %.3f ms, copy %.3f ms, pipeline/copy = %.2f\n", args.c_str(),
                kScenes[scene], t, copy->second, ratio);
    double& w = ShopFloor(scene) ? worst_shop : worst;
    w = std::max(w, ratio);
  }
  std::printf("shop floor (bright, glossy): pipeline/copy = %.2f (target <= 8)\n", worst_shop);
  std::printf("pipeline/copy = %.2f (target <= 4)\n", worst);
  return 0;
}
