// The hardware backends end to end, chosen by job config alone as an integrator would try
// them: the step-gauge scan with the side camera read over GigE Vision (the simulator served as
// a camera on 127.0.0.1, read through the Aravis backend) from `insitu run` and from insitud,
// against the same scan on the simulated camera; a lossy link; and a marking job through the
// LMC board emulator, verified like any simulated marking and against the head driven
// directly. The GigE tests take turns for 127.0.0.1 (RESOURCE_LOCK gige_loopback).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "insitu/daemon/server.h"
#include "insitu/hw/lmc_capture.h"
#include "integration/job_support.h"
#include "support/line_client.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

json ReadReport(const fs::path& dir) {
  std::ifstream f(dir / "report.json");
  return json::parse(f, nullptr, false);
}

// `insitu run` as a process; its exit code.
int RunCli(const std::string& args) {
  const std::string command = std::string(INSITU_BIN) + " run " + args + " > /dev/null 2>&1";
  return std::system(command.c_str());
}

TEST(GigE, TheScanOverGigEMeasuresAsTheSimulatedCamera) {
  const fs::path dir = fs::temp_directory_path() / "insitu_gige_scan";
  fs::remove_all(dir);
  ASSERT_EQ(
      RunCli(testing::JobFile("scan_step_gauge_gige.yaml") + " --out " + (dir / "gige").string()),
      0);
  auto sim = testing::RunShippedJob("scan_step_gauge_gige.yaml", {"machine.camera=sim"},
                                    (dir / "sim").string());
  ASSERT_TRUE(sim.ok()) << sim.status().ToString();
  const json gige = ReadReport(dir / "gige");
  ASSERT_EQ(gige["ok"], true) << gige.dump();
  const json& g = gige["metrics"];
  auto& s = sim->metrics;
  // The frames are the simulator's own bits (hw/aravis test): the same cloud, the same errors.
  // Within noise: a step mean moves by its standard error (rms 0.67 mm over >10000 points:
  // < 0.01 mm) if any frame differed.
  EXPECT_NEAR(g["points"].get<double>(), s["points"], 0.01 * s["points"]);
  for (const char* step : {"3mm", "5mm", "10mm", "15mm"}) {
    const std::string key = std::string("height_error_mean_mm_step_") + step;
    EXPECT_NEAR(g[key].get<double>(), s[key], 0.01) << key;
  }
  EXPECT_NEAR(g["height_error_rms_mm"].get<double>(), s["height_error_rms_mm"], 0.01);
  EXPECT_NEAR(g["length_mm"].get<double>(), s["length_mm"], 0.055);  // the length's own std
  std::printf("GigE: %g points, rms %.4f mm; simulated camera: %g points, rms %.4f mm\n",
              g["points"].get<double>(), g["height_error_rms_mm"].get<double>(), s["points"],
              s["height_error_rms_mm"]);
}

TEST(GigE, ALossyLinkFaultsTheScanWithTheReason) {
  const fs::path dir = fs::temp_directory_path() / "insitu_gige_lossy";
  fs::remove_all(dir);
  const auto t0 = std::chrono::steady_clock::now();
  auto report = testing::RunShippedJob(
      "scan_step_gauge_gige.yaml",
      {"scan.x_start_mm=-3", "scan.x_end_mm=-2", "machine.aravis.lost_packet_ratio=0.05",
       "machine.aravis.frame_timeout_ms=300"},
      dir.string());
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // 5 % of the packets lost: no frame of ~500 packets completes; the first grab says so, the
  // job fails with it and its report says the same.
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.status().code(), StatusCode::kDeviceError);
  const std::string& why = report.status().message();
  EXPECT_NE(why.find("line 0: camera"), std::string::npos) << why;
  EXPECT_NE(why.find("GigE camera at 127.0.0.1"), std::string::npos) << why;
  const json saved = ReadReport(dir);
  EXPECT_EQ(saved["ok"], false);
  EXPECT_NE(saved["error"].get<std::string>().find("GigE camera"), std::string::npos);
  // One grab's timeout at most: 300 ms, and the 20 s the served camera gets for rendering.
  EXPECT_LT(took, 30.0);
}

TEST(GigE, InsitudRunsTheGigEJobByConfigAlone) {
  daemon::ServerOptions o;
  o.port = 0;
  o.results_dir = (fs::temp_directory_path() / "insitu_gige_daemon").string();
  fs::remove_all(o.results_dir);
  o.jobs_dir = INSITU_SOURCE_DIR;
  daemon::Server server(o);
  ASSERT_TRUE(server.Start().ok());
  testing::Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started =
      c.Call(R"({"id": 3, "cmd": "run", "job": "config/jobs/scan_step_gauge_gige.yaml", )"
             R"("set": {"scan.x_start_mm": -3, "scan.x_end_mm": -2}})");
  ASSERT_EQ(started["ok"], true) << started.dump();
  const json end = testing::WaitForJobEnd(c, started["job_id"]);
  ASSERT_EQ(end["status"], "done") << end.dump();
  const json result = c.Call(R"({"id": 4, "cmd": "result", "job_id": ")" +
                             started["job_id"].get<std::string>() + "\"}");
  EXPECT_GT(result["report"]["metrics"]["points"].get<double>(), 1000.0);
}

// Calibration and method 2 over GigE: the accuracy of issue 3 through the Aravis backend.
TEST(GigE, CalibrateAndMeasureToFiftyMicronsOverGigE) {
  const fs::path dir = fs::temp_directory_path() / "insitu_gige_accuracy";
  fs::remove_all(dir);
  const std::vector<std::string> gige{
      "machine.camera=aravis", "machine.aravis.simulate_on=127.0.0.1", "world.camera.model=Fake",
      "world.camera.width_px=2048", "world.camera.height_px=2048"};
  std::vector<std::string> cal_sets = gige;
  cal_sets.push_back("machine.calibration=" + std::string(INSITU_SOURCE_DIR) +
                     "/calib/as_designed_gige.yaml");
  const std::string cal = (dir / "machine.yaml").string();
  auto calibrated = testing::QuickCalibrate(cal, (dir / "calibrate").string(), cal_sets);
  ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  ASSERT_TRUE(calibrated->ok) << calibrated->error;
  std::vector<std::string> sets = gige;
  sets.push_back("machine.calibration=" + cal);
  auto report = testing::RunShippedJob("accuracy_step_gauge.yaml", sets, (dir / "acc").string());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_TRUE(report->ok) << report->error;
  // Issue 3's bound, with the same speckle-limited margin as on the simulated camera.
  EXPECT_LT(report->metrics["height_error_max_abs_binned_mm"], 0.05);
  std::printf("over GigE: binned max %.4f mm, rms %.4f mm\n",
              report->metrics["height_error_max_abs_binned_mm"],
              report->metrics["height_error_rms_mm"]);
}

// A device the job names that is not there stops the job, named; nothing falls back to the
// simulator.
TEST(Devices, AMissingDeviceStopsTheJobByName) {
  const fs::path dir = fs::temp_directory_path() / "insitu_missing_devices";
  fs::remove_all(dir);
  auto camera = testing::RunShippedJob(
      "scan_step_gauge.yaml", {"machine.camera=aravis", "machine.aravis.device=127.0.0.1"},
      (dir / "cam").string());
  ASSERT_FALSE(camera.ok());
  EXPECT_NE(camera.status().message().find("127.0.0.1"), std::string::npos)
      << camera.status().message();
  auto board = testing::RunShippedJob("mark_plate_lmc.yaml", {"machine.lmc.transport=usb"},
                                      (dir / "lmc").string());
  ASSERT_FALSE(board.ok());
  const std::string& why = board.status().message();
  // No board on this bus, or no USB bus at all (a container): either is named.
  EXPECT_TRUE(why.find("9588:9899") != std::string::npos || why.find("libusb") != std::string::npos)
      << why;
  EXPECT_FALSE(fs::exists(dir / "lmc" / "report.json"));  // nothing ran
}

TEST(Lmc, AMarkingJobThroughTheBoardVerifiesAsOnTheHead) {
  const fs::path dir = fs::temp_directory_path() / "insitu_lmc_mark";
  fs::remove_all(dir);
  const std::string capture = (dir / "lmc.pcapng").string();
  auto board = testing::RunShippedJob("mark_plate_lmc.yaml", {"machine.lmc.capture=" + capture},
                                      (dir / "lmc").string());
  auto head = testing::RunShippedJob("mark_plate_lmc.yaml", {"machine.scanner=sim"},
                                     (dir / "head").string());
  ASSERT_TRUE(board.ok()) << board.status().ToString();
  ASSERT_TRUE(head.ok()) << head.status().ToString();
  ASSERT_TRUE(board->ok) << board->error;
  ASSERT_TRUE(head->ok) << head->error;
  auto& b = board->metrics;
  auto& h = head->metrics;
  EXPECT_EQ(b["marks"], h["marks"]);
  EXPECT_EQ(b["points_without_surface"], 0.0);
  // The job's own verification, through the board as on the head: placement (side camera,
  // ~0.02 mm with the as-designed calibration), the 120 um line spacing and the line width
  // (coaxial camera, +-1 um: a 5 um pixel over many lines), the focus.
  EXPECT_LT(b["placement_error_mm"], 0.05);
  EXPECT_NEAR(b["placement_error_mm"], h["placement_error_mm"], 0.01);
  EXPECT_NEAR(b["line_spacing_120_um"], 120.0, 1.5);
  EXPECT_NEAR(b["line_spacing_120_um"], h["line_spacing_120_um"], 1.0);
  EXPECT_NEAR(b["line_width_um"], h["line_width_um"], 1.0);
  EXPECT_NEAR(b["focus_error_max_mm"], h["focus_error_max_mm"], 0.05);
  std::printf(
      "through the LMC board: placement %.3f mm, spacing %.2f um, width %.2f um, focus "
      "%.3f mm; on the head: %.3f mm, %.2f um, %.2f um, %.3f mm\n",
      b["placement_error_mm"], b["line_spacing_120_um"], b["line_width_um"],
      b["focus_error_max_mm"], h["placement_error_mm"], h["line_spacing_120_um"],
      h["line_width_um"], h["focus_error_max_mm"]);

  // The job's whole USB traffic, captured: every list the board received ends once, and one of
  // them is the marking list galvo_list.txt holds.
  const auto decoded = hw::lmc::DecodeCaptureFile(capture);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  std::ifstream galvo(dir / "lmc" / "galvo_list.txt");
  std::string line, marking;
  while (std::getline(galvo, line)) {
    if (!line.empty() && line[0] != '#') marking += line + "\n";
  }
  ASSERT_FALSE(marking.empty());
  std::vector<std::string> lists;
  std::istringstream in(*decoded);
  while (std::getline(in, line)) {
    if (line.rfind("# list ", 0) == 0) {
      lists.emplace_back();
    } else if (!line.empty() && line[0] != '#' && !lists.empty()) {
      lists.back() += line + "\n";
    }
  }
  int found = 0;
  for (const std::string& l : lists) {
    size_t ends = 0;
    for (size_t at = l.find("listEndOfList"); at != std::string::npos;
         at = l.find("listEndOfList", at + 1)) {
      ++ends;
    }
    EXPECT_EQ(ends, 1u);
    found += l == marking;
  }
  EXPECT_EQ(found, 1);
  std::printf("the job's capture: %zu lists, the marking list of %zu commands among them\n",
              lists.size(), static_cast<size_t>(std::count(marking.begin(), marking.end(), '\n')));
}

}  // namespace
}  // namespace insitu
