// The scan at camera speed on the simulated cell: a camera on the scan head's trigger output
// (directly and through the LMC board emulator), the camera's band of rows against its whole
// sensor, a 12-bit camera, pulses the camera cannot take, and cancel during a triggered scan.
// Binned 2x2 frames and 1 mm line spacing keep it fast enough for the default suite.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <utility>

#include "insitu/hw/cell.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/inspect/step_gauge.h"
#include "insitu/job/scan.h"
#include "insitu/sim/world.h"
#include "integration/test_support.h"

namespace insitu {
namespace {

using testing::FastScan;

Result<job::ScanOutput> Scan(hw::Machine& machine, const sim::WorldOptions& world,
                             const job::ScanOptions& o = FastScan()) {
  return job::RunScan(machine, o, vision::StripeOptions{}, testing::PerfectCalibration(world));
}

inspect::StepGaugeResult Evaluate(const job::ScanOutput& out) {
  auto eval = inspect::EvaluateStepGauge(out.cloud, inspect::StepGaugeSpec{});
  EXPECT_TRUE(eval.ok()) << eval.status().ToString();
  return eval.ok() ? *eval : inspect::StepGaugeResult{};
}

// Each step's mean height error of two scans of the same gauge with the same (perfect)
// calibration agrees within 0.01 mm: the stripe noise (~0.15 px, ~0.16 mm/px binned) averages
// over > 500 points per step to ~1 um; what differs between the scans is where the sweep was
// when the exposure began, i.e. which parts of the line each frame saw brighter (speckle and
// the pass count), a few um at most.
void ExpectSameSurface(const job::ScanOutput& a, const job::ScanOutput& b) {
  const inspect::StepGaugeResult ea = Evaluate(a), eb = Evaluate(b);
  ASSERT_EQ(ea.steps.size(), eb.steps.size());
  for (size_t i = 0; i < ea.steps.size(); ++i) {
    EXPECT_GT(eb.steps[i].points, 500) << "step " << i;
    EXPECT_NEAR(ea.steps[i].mean_error_mm, eb.steps[i].mean_error_mm, 0.01) << "step " << i;
  }
  // Nearly the same columns carry the stripe. A 50 ms exposure at 5000 mm/s over a 100 mm
  // line is 2.5 passes: where the sweep was when the exposure began decides which half of the
  // line gets 3 passes and which 2, a 1.5x difference in brightness that moves the dim
  // columns (steep step sides, far plate) across the extraction's thresholds: within 10 %.
  EXPECT_NEAR(static_cast<double>(b.cloud.size()), static_cast<double>(a.cloud.size()),
              0.10 * a.cloud.size());
}

// On the head's pulses each line costs the settle and the exposure only: the frame crosses the
// link while the head goes to the next line. The software-triggered scan waits for the link
// (and the trigger command) before moving on. Same surface, same points.
TEST(ScanSpeed, TheHeadsTriggerMeasuresTheSameSurfaceInLessTime) {
  sim::WorldOptions world;
  auto soft_world = std::make_shared<sim::SimWorld>(world);
  hw::Machine soft = hw::MakeSimMachine(soft_world);
  auto software = Scan(soft, world);
  ASSERT_TRUE(software.ok()) << software.status().ToString();
  EXPECT_EQ(software->stats.trigger, "software");

  world.camera.head_trigger = true;
  auto trig_world = std::make_shared<sim::SimWorld>(world);
  hw::Machine trig = hw::MakeSimMachine(trig_world);
  int last_done = -1;
  auto triggered = job::RunScan(trig, FastScan(), vision::StripeOptions{},
                                testing::PerfectCalibration(world), [&](int done, int total) {
                                  EXPECT_GE(done, last_done);
                                  EXPECT_EQ(total, 20);
                                  last_done = done;
                                });
  ASSERT_TRUE(triggered.ok()) << triggered.status().ToString();
  EXPECT_EQ(last_done, 20);
  EXPECT_EQ(triggered->stats.trigger, "head");
  EXPECT_EQ(triggered->stats.lines, 20);
  EXPECT_EQ(trig_world->ignored_pulses(), 0);
  ExpectSameSurface(*software, *triggered);

  // The machine time each way: on the head's pulses a line costs the settle (5 ms) and the
  // dwell (the exposure and 0.5 ms; the binned band crosses GigE in ~3 ms, faster than the
  // 50 ms exposure, so the link does not bound it), the last frame's link after it; in
  // software a line costs the settle, the exposure and the link (streaming: no processing
  // waits).
  const job::ScanOptions o = FastScan();
  const double line_s = (o.settle_ms + o.exposure_ms) * 1e-3;
  EXPECT_GT(triggered->stats.machine_time_s, 20 * line_s);
  EXPECT_LT(triggered->stats.machine_time_s, 20 * (line_s + 0.5e-3) + 0.02);
  EXPECT_LT(triggered->stats.machine_time_s, software->stats.machine_time_s);
  std::printf("machine time: software trigger %.3f s, head trigger %.3f s (20 lines)\n",
              software->stats.machine_time_s, triggered->stats.machine_time_s);
}

// The same, with the LMC board emulator as the head: the scan is one list on the board whose
// trigger output bit is wired to the camera; the board raises it once per line.
TEST(ScanSpeed, TheBoardsTriggerOutputPacesTheCamera) {
  hw::MachineConfig config;
  config.world.camera.head_trigger = true;
  config.scanner = "lmc";
  config.lmc.transport = "sim_board";
  hw::lmc::BoardOptions& b = config.lmc.board;
  b.lens_mm = 163.0;  // the simulated head's +-70 mm field, 2.5 um per unit
  b.focus = hw::lmc::Focus::kDaZWord;
  b.z_units_per_mm = 1000.0;
  b.focus_range_mm = 25.0;
  b.poll_ms = 1;
  b.trigger_port = 0x0002;
  auto machine = hw::CreateMachine(config);
  ASSERT_TRUE(machine.ok()) << machine.status().ToString();
  EXPECT_TRUE(machine->scanner->info().trigger_output);
  auto out = Scan(*machine, config.world);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  EXPECT_EQ(out->stats.trigger, "head");
  EXPECT_EQ(out->stats.lines, 20);

  hw::Machine direct = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(config.world));
  auto reference = Scan(direct, config.world);
  ASSERT_TRUE(reference.ok()) << reference.status().ToString();
  ExpectSameSurface(*reference, *out);
  // On the board's clock a line costs the jump to it (from where the last pass stopped to the
  // line's nearer end: at most half a line and a spacing, at the sweep's 5000 mm/s), the
  // settle, the pulse (0.1 ms) and the dwell (exposure + 0.5 ms); the last frame's link after.
  const job::ScanOptions o = FastScan();
  const double length = o.y_end_mm - o.y_start_mm;
  const double line_s = (o.settle_ms + 0.1 + o.exposure_ms + 0.5) * 1e-3;
  const double jump_s = (0.5 * length + o.line_spacing_mm) / o.speed_mm_per_s;
  EXPECT_GT(out->stats.machine_time_s, 20 * line_s);
  EXPECT_LT(out->stats.machine_time_s, 20 * (line_s + jump_s) + 0.02);
  std::printf("machine time: board-triggered %.3f s, head-triggered %.3f s\n",
              out->stats.machine_time_s, reference->stats.machine_time_s);

  // A sweep the board refuses before it starts (a settle longer than its list delay holds)
  // is the board's error, at once, not a camera waiting for a pulse.
  job::ScanOptions slow = o;
  slow.settle_ms = 700.0;
  const auto t0 = std::chrono::steady_clock::now();
  auto refused_sweep = Scan(*machine, config.world, slow);
  ASSERT_FALSE(refused_sweep.ok());
  EXPECT_EQ(refused_sweep.status().code(), StatusCode::kOutOfRange)
      << refused_sweep.status().ToString();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 10.0);
  // ... and the cell scans again after it.
  auto again = Scan(*machine, config.world);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->stats.lines, 20);

  // A board without the output cannot pace a camera that waits for it.
  config.lmc.board.trigger_port = 0;
  auto unwired = hw::CreateMachine(config);
  ASSERT_TRUE(unwired.ok()) << unwired.status().ToString();
  auto refused = Scan(*unwired, config.world);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("trigger_port"), std::string::npos)
      << refused.status().message();
}

// A pulse while the camera still exposes is lost, as on a real camera; the scan then stops on
// the missing frame and says how many pulses were ignored.
TEST(ScanSpeed, PulsesTheCameraCannotTakeAreCountedNotSilent) {
  sim::WorldOptions world;
  world.camera.head_trigger = true;
  sim::SimWorld w(world);
  ASSERT_TRUE(w.SetExposure(20e3).ok());
  ASSERT_TRUE(w.StartPointerLine({0, -40, 0}, {0, 40, 0}, 5000).ok());
  w.ArmTrigger(true);
  w.SetHeadRunning(true);
  w.TriggerPulse();
  w.Advance(0.010);  // half way through the 20 ms exposure
  w.TriggerPulse();
  w.Advance(0.015);
  w.TriggerPulse();
  w.SetHeadRunning(false);
  EXPECT_EQ(w.ignored_pulses(), 1);
  auto first = w.TakeTriggered(10.0);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_DOUBLE_EQ(first->timestamp_s, 0.0);
  auto second = w.TakeTriggered(10.0);
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  EXPECT_DOUBLE_EQ(second->timestamp_s, 0.025);
  auto none = w.TakeTriggered(10.0);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("1 pulses came while the camera was exposing"),
            std::string::npos)
      << none.status().message();
  // The clock waited for the second frame's link after the head stopped.
  EXPECT_GT(w.now_s(), 0.025 + 0.020);
}

// A camera fault during a triggered scan is the camera's error (the device fault a daemon
// reports as such), not a cancel: the head stopped because the scan stopped it.
TEST(ScanSpeed, ACameraFaultInATriggeredScanIsNotACancel) {
  sim::WorldOptions world;
  world.camera.head_trigger = true;
  world.faults.camera_drop_frame_at = 3;
  hw::Machine machine = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(world));
  auto out = Scan(machine, world);
  ASSERT_FALSE(out.ok());
  EXPECT_EQ(out.status().code(), StatusCode::kDeviceError) << out.status().ToString();
  EXPECT_NE(out.status().message().find("packets lost"), std::string::npos)
      << out.status().message();
}

// Cancel reaches the head between lines: the scan ends cancelled, the pointer is off and the
// camera is back on software trigger (a single grab gets its frame).
TEST(ScanSpeed, CancelStopsATriggeredScan) {
  sim::WorldOptions world;
  world.camera.head_trigger = true;
  auto w = std::make_shared<sim::SimWorld>(world);
  hw::Machine machine = hw::MakeSimMachine(w);
  std::atomic<bool> cancel{false};
  auto out = job::RunScan(
      machine, FastScan(), vision::StripeOptions{}, testing::PerfectCalibration(world),
      [&](int done, int) {
        if (done >= 3) cancel.store(true);
      },
      &cancel);
  ASSERT_FALSE(out.ok());
  EXPECT_EQ(out.status().code(), StatusCode::kCancelled) << out.status().ToString();
  auto grab = machine.camera->Grab();
  ASSERT_TRUE(grab.ok()) << grab.status().ToString();
  EXPECT_EQ(grab->height * grab->binning, world.camera.height_px);  // the whole sensor again
  EXPECT_TRUE(w->last_truth().beam_pixels.empty());                 // the pointer is off
}

// The band of rows measures what the whole sensor measures: the band holds every row the
// stripe can reach, the noise of each sensor row is the same either way, so the same columns
// give the same centres; the band only reads fewer rows.
TEST(ScanSpeed, TheBandMeasuresWhatTheWholeSensorDoes) {
  sim::WorldOptions world;
  job::ScanOutput runs[2];
  for (int k = 0; k < 2; ++k) {
    hw::Machine machine = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(world));
    job::ScanOptions o = FastScan();
    o.region = k == 1;
    auto out = Scan(machine, world, o);
    ASSERT_TRUE(out.ok()) << out.status().ToString();
    runs[k] = std::move(*out);
  }
  EXPECT_EQ(runs[0].stats.region_rows, world.camera.height_px);
  EXPECT_LT(runs[1].stats.region_rows, world.camera.height_px / 2);
  std::map<std::pair<int, float>, Eigen::Vector3f> whole;
  std::map<std::pair<int, float>, float> whole_v;
  for (const geometry::CloudPoint& p : runs[0].cloud) {
    whole[{p.line, p.pixel_u}] = p.point_in_galvo;
    whole_v[{p.line, p.pixel_u}] = p.pixel_v;
  }
  size_t same = 0;
  for (const geometry::CloudPoint& p : runs[1].cloud) {
    const auto it = whole.find({p.line, p.pixel_u});
    if (it == whole.end()) continue;
    // The same pixels give the same centre up to where the sweep was when each exposure
    // began (the band's frames cross the link sooner, so each line starts at another phase):
    // a gray level more or less at a stripe's peak here and there, which moves a centre by
    // ~1 / 40 px (the weights above K sum to ~40 levels), ~0.02 px, ~5 um with the lever of
    // the height; far below the stripe's own noise (0.15 px at 0.16 mm/px binned, ~0.024 mm).
    EXPECT_LT((it->second - p.point_in_galvo).norm(), 0.010f)
        << "line " << p.line << " u " << p.pixel_u << " v " << p.pixel_v << " (band from row "
        << runs[1].stats.region_first_row << "; whole sensor: " << whole_v[{p.line, p.pixel_u}]
        << ")";
    ++same;
  }
  // Every band point has its twin; the whole sensor may add a few outside the band (light
  // scattered far from the stripe, which the band never reads).
  EXPECT_EQ(same, runs[1].cloud.size());
  EXPECT_GE(same, static_cast<size_t>(0.995 * runs[0].cloud.size()));
  EXPECT_LT(runs[1].stats.machine_time_s, runs[0].stats.machine_time_s);
  std::printf("band %d rows: %zu points, %.3f s; whole sensor: %zu points, %.3f s\n",
              runs[1].stats.region_rows, runs[1].cloud.size(), runs[1].stats.machine_time_s,
              runs[0].cloud.size(), runs[0].stats.machine_time_s);
}

// Far out in the field the light sheet leans (its apex is the mirrors, 300 mm up): at
// x = 55 mm a surface 15 mm up is lit ~2.7 mm further in than its x. The band follows the
// plane the scan triangulates with, so the gauge moved out there loses no point to it.
TEST(ScanSpeed, TheBandFollowsTheLeaningSheetAtTheFieldsEdge) {
  sim::WorldOptions world;
  world.part.position_mm = {50.0, 0.0};
  job::ScanOptions o = FastScan();
  o.x_start_mm = 40.5;
  o.x_end_mm = 59.5;
  o.height_range_mm = {-1.0, 16.0};  // the gauge's 15 mm top and the plate
  size_t points[2];
  for (int k = 0; k < 2; ++k) {
    hw::Machine machine = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(world));
    o.region = k == 1;
    auto out = Scan(machine, world, o);
    ASSERT_TRUE(out.ok()) << out.status().ToString();
    points[k] = out->cloud.size();
    if (k == 1) {
      EXPECT_LT(out->stats.region_rows, world.camera.height_px / 2);
    }
  }
  EXPECT_GT(points[0], 5000u);
  EXPECT_EQ(points[1], points[0]);
}

// A 12-bit camera sees the same light: the scan's gray levels are 8-bit ones scaled to the
// frame (StripeOptions::ForBitDepth), so the same columns pass and the heights agree.
TEST(ScanSpeed, ATwelveBitCameraMeasuresWhatAnEightBitOneDoes) {
  sim::WorldOptions world;
  hw::Machine eight = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(world));
  auto a = Scan(eight, world);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  world.camera.bit_depth = 12;
  hw::Machine twelve = hw::MakeSimMachine(std::make_shared<sim::SimWorld>(world));
  auto b = Scan(twelve, world);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  ExpectSameSurface(*a, *b);
  // Background columns are not searched: the valid fraction matches the 8-bit scan's within
  // 2 % (had the 12-bit noise passed raw 8-bit thresholds, "two peaks" would swamp it).
  const auto fraction = [](const job::ScanOutput& o) {
    return static_cast<double>(o.stats.valid) / o.stats.scan_lines_examined;
  };
  EXPECT_NEAR(fraction(*b), fraction(*a), 0.02);
}

}  // namespace
}  // namespace insitu
