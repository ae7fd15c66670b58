// Jobs through the command socket, as an integrator runs them: progress events while a scan
// runs, cancel while the head marks (the laser off within one head tick, measured against the
// simulator's pulse record), a stage that does not arrive, the queue policy, a client that
// leaves mid-job, and shutdown reserved to an admin client.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <memory>
#include <string>
#include <vector>

#include "insitu/daemon/server.h"
#include "insitu/hw/cell.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/sim/world.h"
#include "support/line_client.h"

namespace insitu::daemon {
namespace {

using testing::Client;
using testing::Pong;
using testing::WaitForJobEnd;
using json = nlohmann::json;

ServerOptions Loopback(const char* results) {
  ServerOptions o;
  o.port = 0;
  o.results_dir = (std::filesystem::temp_directory_path() / results).string();
  std::filesystem::remove_all(o.results_dir);
  o.jobs_dir = INSITU_SOURCE_DIR;
  return o;
}

// The shipped scan job cut to 3 lines: about a second.
const char* kShortScan =
    R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.x_start_mm": -3.0, )"
    R"("scan.x_end_mm": -2.0})";

// One request line (the job text may span lines: it is sent compacted).
std::string RunLine(int id, const std::string& job) {
  return json::parse(R"({"id": )" + std::to_string(id) + R"(, "cmd": "run", )" + job + "}").dump();
}

// Arms the machine, runs the short scan and waits for it: the machine serves the next job.
std::string TheNextJobRuns(Client& c) {
  if (c.Call(R"({"id": "a", "cmd": "arm"})")["ok"] != true) return "arm refused";
  const json next = c.Call(RunLine(0, kShortScan));
  if (next["ok"] != true) return next.dump();
  return WaitForJobEnd(c, next["job_id"]).value("status", "no end");
}

TEST(Jobs, AScanReportsItsProgressLineByLine) {
  Server server(Loopback("insitu_jobs_progress"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(3, kShortScan));
  ASSERT_EQ(started["ok"], true) << started.dump();
  std::vector<json> events;
  const json end = WaitForJobEnd(c, started["job_id"], &events);
  ASSERT_EQ(end["status"], "done") << end.dump();
  std::vector<double> done;
  for (const json& e : events) {
    if (e.value("event", "") != "progress") continue;
    EXPECT_EQ(e["job_id"], started["job_id"]);
    EXPECT_EQ(e["phase"], "scan");
    EXPECT_EQ(e["unit"], "lines");
    EXPECT_EQ(e["total"], 3.0);
    done.push_back(e["done"].get<double>());
  }
  // The first update (0 of 3) and the last (3 of 3) always come; more in between at most
  // every 0.2 s.
  ASSERT_GE(done.size(), 2u);
  EXPECT_EQ(done.front(), 0.0);
  EXPECT_EQ(done.back(), 3.0);
  EXPECT_TRUE(std::is_sorted(done.begin(), done.end()));
}

// The simulated machine of the jobs this test runs, kept for its truth: the "sim" backend is
// replaced by one that builds the same machine and remembers its world.
std::shared_ptr<sim::SimWorld> g_world;

void KeepTheSimWorld() {
  hw::RegisterBackend("sim", [](const hw::MachineConfig& config) -> Result<hw::Machine> {
    INSITU_RETURN_IF_ERROR(config.world.Validate().Prefixed("world"));
    g_world = std::make_shared<sim::SimWorld>(config.world);
    return hw::CreateMachineOn(config, g_world);
  });
}

// A 5 mm plate hatched at 20 um on the arc, marked at 500 mm/s: about 2.7 s of list, run in
// real time (real_time_factor 1) so a cancel can arrive while the head marks. A few scan
// lines over the crown give the surface; method 1 with the as-designed calibration is enough
// here (the test is about stopping, not accuracy).
const char* kLongMark = R"("job": {
  "job": "mark",
  "machine": {"backend": "sim", "calibration": "calib/as_designed.yaml"},
  "world": "config/worlds/default.yaml",
  "world_changes": {"real_time_factor": 1.0, "part": {"kind": "arc", "position_mm": [1.0, -2.0]}},
  "scan": {"x_start_mm": -4.0, "x_end_mm": 4.0, "line_spacing_mm": 0.5,
           "y_start_mm": -50.0, "y_end_mm": 50.0},
  "camera": {"exposure_ms": 50.0},
  "reconstruction": {"method": 1},
  "pattern": {"kind": "svg", "file": "config/patterns/plate.svg"},
  "placement": {"anchor": "centre", "offset_mm": [1.0, -2.0]},
  "hatch": {"spacing_mm": 0.02, "angles_deg": [0.0]},
  "laser": {"power": 0.5, "frequency_khz": 30.0, "mark_speed_mm_per_s": 500.0,
            "jump_speed_mm_per_s": 5000.0, "laser_on_delay_us": 100.0,
            "laser_off_delay_us": 200.0, "jump_delay_us": 300.0, "mark_delay_us": 250.0},
  "head": {"bits": 20},
  "verify": {"enabled": false}})";

TEST(Jobs, CancelWhileMarkingTurnsTheLaserOffWithinOneHeadTick) {
  KeepTheSimWorld();
  Server server(Loopback("insitu_jobs_cancel_mark"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(3, kLongMark));
  ASSERT_EQ(started["ok"], true) << started.dump();

  // Wait until the head has marked for 0.5 s of its list.
  double list_ms = 0.0;
  for (;;) {
    const std::string line = c.ReadLine();
    ASSERT_FALSE(line.empty()) << "no marking progress";
    const json e = json::parse(line);
    ASSERT_FALSE(e.value("event", "") == "job" && e.value("status", "") != "running")
        << "the job ended before marking: " << line;
    if (e.value("event", "") == "progress" && e["phase"] == "mark" &&
        e["done"].get<double>() >= 500.0) {
      EXPECT_EQ(e["unit"], "ms");
      list_ms = e["total"].get<double>();
      break;
    }
  }
  ASSERT_GT(list_ms, 1500.0);  // the list is long enough for the cancel to land in it
  EXPECT_TRUE(server.state().laser_allowed());
  const auto cancel_sent = std::chrono::steady_clock::now();
  EXPECT_EQ(c.Call(R"({"id": 4, "cmd": "cancel"})")["job_id"], started["job_id"]);
  const json end = WaitForJobEnd(c, started["job_id"]);
  ASSERT_EQ(end["status"], "cancelled") << end.dump();
  EXPECT_NE(end["reason"].get<std::string>().find("list aborted"), std::string::npos) << end.dump();
  EXPECT_FALSE(server.state().laser_allowed());

  // The head's side (simulator truth): it saw the abort part-way through the list and no
  // pulse fired after the tick on which it did.
  ASSERT_TRUE(g_world != nullptr);
  const sim::ListAbortTruth& abort = g_world->last_list_abort();
  ASSERT_TRUE(abort.aborted);
  EXPECT_GT(abort.seen_at_s - abort.list_start_s, 0.5);
  EXPECT_LT(abort.seen_at_s, abort.list_end_s - 0.5);
  const auto& pulses = g_world->mark_pulses();
  ASSERT_FALSE(pulses.empty());
  double last_pulse_s = 0.0;
  for (const sim::MarkPulse& p : pulses) last_pulse_s = std::max(last_pulse_s, p.t_s);
  const double tick_s = g_world->options().scan_head.clock_us * 1e-6;
  EXPECT_LE(last_pulse_s, abort.seen_at_s + 1e-9);  // off on the tick that saw the abort
  EXPECT_GT(last_pulse_s, abort.list_start_s + 0.5 - tick_s);
  // Cancel to head: socket round trip, the daemon's handler and the head's 1 ms pacing sleep.
  // 250 ms bounds these on a loaded 2-core machine; the head itself polls on every 10 us tick.
  const double latency_s = std::chrono::duration<double>(abort.seen_wall - cancel_sent).count();
  std::printf("cancel to head: %.1f ms; aborted %.1f of %.1f ms into the list; last pulse %.1f us "
              "before the abort tick\n",
              latency_s * 1e3, (abort.seen_at_s - abort.list_start_s) * 1e3,
              (abort.list_end_s - abort.list_start_s) * 1e3, (abort.seen_at_s - last_pulse_s) * 1e6);
  EXPECT_LT(latency_s, 0.25);
  EXPECT_GT(latency_s, -0.001);

  // The report says what happened; the next job runs.
  const json result = c.Call(R"({"id": 5, "cmd": "result", "job_id": ")" +
                             started["job_id"].get<std::string>() + "\"}");
  EXPECT_EQ(result["result"]["status"], "cancelled");
  EXPECT_EQ(TheNextJobRuns(c), "done");
}

// A streaming scan (frames processed while the next lines are taken) stops on cancel between
// lines, ends cancelled, and the machine serves the next job.
TEST(Jobs, CancelStopsAStreamingScan) {
  Server server(Loopback("insitu_jobs_cancel_scan"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(
      3, R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.streaming": true})"));
  ASSERT_EQ(started["ok"], true) << started.dump();
  // The first progress of the scan phase past its start: lines are being taken.
  for (int k = 0; k < 1000; ++k) {
    const json e = json::parse(c.ReadLine(), nullptr, false);
    if (e.is_object() && e.value("event", "") == "progress" && e.value("done", 0.0) > 0) break;
  }
  ASSERT_EQ(c.Call(R"({"id": 4, "cmd": "cancel"})")["ok"], true);
  const json end = WaitForJobEnd(c, started["job_id"]);
  EXPECT_EQ(end["status"], "cancelled") << end.dump();
  EXPECT_EQ(TheNextJobRuns(c), "done");
}

// The calibrate job lowers the stage first: a stuck stage faults it there, by name.
TEST(Jobs, AStageThatDoesNotArriveFaultsTheJob) {
  Server server(Loopback("insitu_jobs_stage"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(
      3, R"("job": "config/jobs/calibrate.yaml", "set": {"world.faults.stage_stuck": true})"));
  ASSERT_EQ(started["ok"], true) << started.dump();
  const json end = WaitForJobEnd(c, started["job_id"]);
  ASSERT_EQ(end["status"], "faulted") << end.dump();
  EXPECT_NE(end["reason"].get<std::string>().find("stage did not arrive"), std::string::npos);
  EXPECT_FALSE(server.state().laser_allowed());
  EXPECT_TRUE(Pong(c));
  EXPECT_EQ(TheNextJobRuns(c), "done");
}

// The next prompt event asking the operator (machine.operator: person); null if none comes.
json WaitForPrompt(Client& c) {
  for (int k = 0; k < 10000; ++k) {
    const std::string line = c.ReadLine();
    if (line.empty()) return nullptr;
    const json j = json::parse(line, nullptr, false);
    if (j.is_object() && j.value("event", "") == "prompt" && j.contains("request")) return j;
  }
  return nullptr;
}

// A cell whose operator is a person: the calibrate job asks through prompt events, `status`
// shows the waiting prompt, `ack` answers it (the simulator's hands then place the board), and
// an abort ends the job cancelled with the operator's reason.
TEST(Jobs, TheOperatorIsAskedThroughPromptsAndAnswersWithAck) {
  Server server(Loopback("insitu_jobs_prompt"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  EXPECT_EQ(c.Call(R"({"id": 2, "cmd": "ack", "prompt_id": 1})")["error"]["code"], "wrong_state");
  EXPECT_EQ(c.Call(R"({"id": 2, "cmd": "ack"})")["error"]["code"], "bad_argument");
  ASSERT_EQ(c.Call(R"({"id": 3, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(
      4, R"("job": "config/jobs/calibrate.yaml", "set": {"machine.operator": "person"})"));
  ASSERT_EQ(started["ok"], true) << started.dump();
  const json first = WaitForPrompt(c);
  ASSERT_TRUE(first.is_object());
  EXPECT_EQ(first["job_id"], started["job_id"]);
  EXPECT_NE(first["request"].get<std::string>().find("view 1 of"), std::string::npos)
      << first.dump();
  const json status = c.Call(R"({"id": 5, "cmd": "status"})");
  EXPECT_EQ(status["prompt"]["prompt_id"], first["prompt_id"]) << status.dump();
  EXPECT_EQ(c.Call(R"({"id": 6, "cmd": "ack", "prompt_id": 999})")["error"]["code"], "not_found");
  EXPECT_EQ(c.Call(R"({"id": 7, "cmd": "ack", "prompt_id": -1})")["error"]["code"],
            "bad_argument");
  ASSERT_EQ(c.Call(json({{"id", 8}, {"cmd", "ack"}, {"prompt_id", first["prompt_id"]}}).dump())["ok"],
            true);
  const json second = WaitForPrompt(c);
  ASSERT_TRUE(second.is_object());
  EXPECT_NE(second["request"].get<std::string>().find("view 2 of"), std::string::npos)
      << second.dump();
  // The first prompt's answer again (a double click) does not confirm the second.
  EXPECT_EQ(c.Call(json({{"id", 10}, {"cmd", "ack"}, {"prompt_id", first["prompt_id"]}}).dump())
                ["error"]["code"],
            "not_found");
  ASSERT_EQ(c.Call(json({{"id", 9}, {"cmd", "ack"}, {"prompt_id", second["prompt_id"]},
                         {"abort", true}}).dump())["ok"],
            true);
  const json end = WaitForJobEnd(c, started["job_id"]);
  ASSERT_EQ(end["status"], "cancelled") << end.dump();
  EXPECT_NE(end["reason"].get<std::string>().find("the operator aborted"), std::string::npos)
      << end.dump();
  EXPECT_FALSE(server.state().laser_allowed());
}

// A cancel ends a job that waits for the operator.
TEST(Jobs, ACancelEndsTheWaitForTheOperator) {
  Server server(Loopback("insitu_jobs_prompt_cancel"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json started = c.Call(RunLine(
      3, R"("job": "config/jobs/calibrate.yaml", "set": {"machine.operator": "person"})"));
  ASSERT_EQ(started["ok"], true) << started.dump();
  ASSERT_TRUE(WaitForPrompt(c).is_object());
  ASSERT_EQ(c.Call(R"({"id": 4, "cmd": "cancel"})")["ok"], true);
  const json end = WaitForJobEnd(c, started["job_id"]);
  EXPECT_EQ(end["status"], "cancelled") << end.dump();
  EXPECT_TRUE(c.Call(R"({"id": 5, "cmd": "status"})")["prompt"].is_null());
}

// A job file in the jobs folder, made from the shipped profiler calibration: files named by
// absolute paths into the source tree, its output `mount_file`.
std::filesystem::path ProfilerJob(const std::filesystem::path& jobs, const std::string& world,
                                  const std::string& mount_file) {
  const std::string src = INSITU_SOURCE_DIR;
  std::ifstream in(src + "/config/jobs/calibrate_profiler.yaml");
  std::stringstream text;
  text << in.rdbuf();
  std::string job = text.str();
  const auto swap = [&job](const std::string& from, const std::string& to) {
    job.replace(job.find(from), from.size(), to);
  };
  swap("../worlds/default.yaml", world);
  swap("../../out/calib/machine.yaml", src + "/calib/as_designed.yaml");
  swap("../../out/calib/profiler_mount.yaml", mount_file);
  std::filesystem::create_directories(jobs);
  const std::filesystem::path path = jobs / "profiler.yaml";
  std::ofstream(path) << job;
  return path;
}

// What a job reads lies inside the daemon's read roots; what it writes goes under its results
// folder, whatever its job file says; a daemon with a cell of its own keeps clients off it.
TEST(Jobs, AJobReadsInsideTheRootsAndWritesUnderItsResults) {
  const std::filesystem::path tmp = std::filesystem::temp_directory_path() / "insitu_jobs_roots";
  std::filesystem::remove_all(tmp);
  const std::string src = INSITU_SOURCE_DIR;
  ServerOptions o = Loopback("insitu_jobs_roots_results");
  o.jobs_dir = (tmp / "jobs").string();
  o.read_roots = {o.jobs_dir, src + "/config", src + "/calib"};
  Server server(o);
  ProfilerJob(tmp / "jobs", "/etc/hostname", (tmp / "elsewhere" / "mount.yaml").string());
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  // A world outside the roots: refused before it is read, naming the key, not the file.
  const json outside = c.Call(RunLine(3, R"("job": "profiler.yaml")"));
  ASSERT_EQ(outside["ok"], false);
  const std::string why = outside["error"]["message"];
  EXPECT_NE(why.find("world"), std::string::npos) << why;
  EXPECT_NE(why.find("read_roots"), std::string::npos) << why;
  // Inside: it runs, and the mount file lands in its results folder, not where it said.
  ProfilerJob(tmp / "jobs", src + "/config/worlds/default.yaml",
              (tmp / "elsewhere" / "mount.yaml").string());
  const json started = c.Call(RunLine(4, R"("job": "profiler.yaml")"));
  ASSERT_EQ(started["ok"], true) << started.dump();
  const json end = WaitForJobEnd(c, started["job_id"]);
  ASSERT_EQ(end["status"], "done") << end.dump();
  EXPECT_FALSE(std::filesystem::exists(tmp / "elsewhere" / "mount.yaml"));
  const json result = c.Call(json({{"id", 5}, {"cmd", "result"}, {"job_id", started["job_id"]}}).dump());
  const std::filesystem::path dir =
      std::filesystem::path(o.results_dir) / started["job_id"].get<std::string>();
  EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / "output_mount.yaml")) << dir;
  EXPECT_NE(result["report"]["warnings"].dump().find("written to"), std::string::npos)
      << result["report"].dump();
}

TEST(Jobs, ADaemonsCellIsNotAClientsToChange) {
  ServerOptions o = Loopback("insitu_jobs_cell");
  o.machine_sets = {"machine={}", "machine.backend=sim",
                    std::string("machine.calibration=") + INSITU_SOURCE_DIR +
                        "/calib/as_designed.yaml"};
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 0, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "arm"})")["ok"], true);
  const json refused = c.Call(RunLine(2, R"("job": "config/jobs/scan_step_gauge.yaml", )"
                                         R"("set": {"machine.stage": "none"})"));
  EXPECT_EQ(refused["error"]["code"], "bad_argument") << refused.dump();
  EXPECT_NE(refused["error"]["message"].get<std::string>().find("machine.stage"),
            std::string::npos);
  EXPECT_EQ(TheNextJobRuns(c), "done");
}

// A job whose cell lacks a role it needs is refused at `run`, by the role's key, and the machine
// stays armed for the next one: the coaxial field calibration needs no stage, the side one does.
TEST(Jobs, AJobNeedingARoleTheCellLacksIsRefusedAtRun) {
  Server server(Loopback("insitu_jobs_roles"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 0, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "arm"})")["ok"], true);
  const json refused = c.Call(RunLine(
      2, R"("job": "config/jobs/field_calibration.yaml", "set": {"machine.stage": "none"})"));
  EXPECT_EQ(refused["error"]["code"], "wrong_state") << refused.dump();
  EXPECT_NE(refused["error"]["message"].get<std::string>().find("machine.stage"),
            std::string::npos);
  const json scan = c.Call(RunLine(3, R"("job": "config/jobs/scan_step_gauge.yaml", )"
                                      R"("set": {"machine.camera": "none"})"));
  EXPECT_NE(scan["error"]["message"].get<std::string>().find("machine.camera"), std::string::npos)
      << scan.dump();
  EXPECT_EQ(c.Call(R"({"id": 4, "cmd": "status"})")["state"], "armed");
  EXPECT_EQ(TheNextJobRuns(c), "done");
}

TEST(Jobs, RefusedOrQueuedAsConfigured) {
  {
    Server server(Loopback("insitu_jobs_refuse"));
    ASSERT_TRUE(server.Start().ok());
    Client c(server.port());
    ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "arm"})")["ok"], true);
    ASSERT_EQ(c.Call(RunLine(2, kShortScan))["ok"], true);
    EXPECT_EQ(c.Call(RunLine(3, kShortScan))["error"]["code"], "wrong_state");
  }
  ServerOptions o = Loopback("insitu_jobs_queue");
  o.queue = true;
  o.max_queued = 2;
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json a = c.Call(RunLine(3, kShortScan));
  const json b = c.Call(RunLine(4, kShortScan));
  const json x = c.Call(RunLine(5, kShortScan));
  ASSERT_EQ(a["ok"], true) << a.dump();
  EXPECT_FALSE(a.contains("queued"));
  ASSERT_EQ(b["queued"], true) << b.dump();
  EXPECT_EQ(b["position"], 1);
  ASSERT_EQ(x["position"], 2) << x.dump();
  EXPECT_EQ(c.Call(RunLine(6, kShortScan))["error"]["code"], "wrong_state");  // full
  const json status = c.Call(R"({"id": 7, "cmd": "status"})");
  EXPECT_EQ(status["job_id"], a["job_id"]);
  EXPECT_EQ(status["queued"].size(), 2u);
  // A queued job can be taken out by its id; the others run in turn.
  EXPECT_EQ(c.Call(R"({"id": 8, "cmd": "cancel", "job_id": ")" + x["job_id"].get<std::string>() +
                   "\"}")["ok"],
            true);
  EXPECT_EQ(WaitForJobEnd(c, a["job_id"])["status"], "done");
  EXPECT_EQ(WaitForJobEnd(c, b["job_id"])["status"], "done");
  const json list = c.Call(R"({"id": 9, "cmd": "list_results"})");
  ASSERT_EQ(list["results"].size(), 3u);
  EXPECT_EQ(list["results"][0]["status"], "cancelled");  // x, newest
  EXPECT_EQ(list["results"][0]["reason"], "cancelled before it ran");

  // A fault ends the queue: what waits behind it is not run on a machine in doubt.
  ASSERT_EQ(c.Call(R"({"id": 10, "cmd": "arm"})")["ok"], true);
  const json bad = c.Call(
      RunLine(11, R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.x_start_mm": -3.0, )"
                  R"("scan.x_end_mm": -2.0, "world.faults.camera_timeout_at_frame": 1})"));
  const json behind = c.Call(RunLine(12, kShortScan));
  ASSERT_EQ(behind["queued"], true) << behind.dump();
  EXPECT_EQ(WaitForJobEnd(c, bad["job_id"])["status"], "faulted");
  const json dropped = WaitForJobEnd(c, behind["job_id"]);
  EXPECT_EQ(dropped["status"], "cancelled");
  EXPECT_NE(dropped["reason"].get<std::string>().find("not run"), std::string::npos);
  EXPECT_EQ(c.Call(R"({"id": 13, "cmd": "status"})")["state"], "faulted");
}

TEST(Jobs, AClientThatLeavesMidJobLeavesTheJobRunning) {
  Server server(Loopback("insitu_jobs_leaver"));
  ASSERT_TRUE(server.Start().ok());
  std::string id;
  {
    Client leaver(server.port());
    ASSERT_EQ(leaver.Call(R"({"id": 1, "cmd": "arm"})")["ok"], true);
    const json started = leaver.Call(RunLine(2, kShortScan));
    ASSERT_EQ(started["ok"], true);
    id = started["job_id"];
  }
  Client c(server.port());
  for (int k = 0; k < 300 && c.Call(R"({"id": 3, "cmd": "status"})")["state"] == "running"; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  const json result = c.Call(R"({"id": 4, "cmd": "result", "job_id": ")" + id + "\"}");
  EXPECT_EQ(result["result"]["status"], "done");
  EXPECT_EQ(result["report"]["ok"], true);
}

// A job with a bad value is refused at `run`, by file, line and key, with the machine
// untouched (still armed, nothing recorded).
TEST(Jobs, ABadJobIsRefusedBeforeAnythingMoves) {
  Server server(Loopback("insitu_jobs_bad"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "arm"})")["ok"], true);
  const json reply = c.Call(RunLine(
      2, R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.speed_mm_per_s": -5})"));
  EXPECT_EQ(reply["error"]["code"], "bad_argument") << reply.dump();
  const std::string message = reply["error"]["message"];
  EXPECT_NE(message.find("speed_mm_per_s"), std::string::npos) << message;
  const json typo = c.Call(RunLine(
      3, R"("job": {"job": "scan", "machine": {"backend": "sim", "calibration": )"
         R"("calib/as_designed.yaml"}, "world": "config/worlds/default.yaml", "scna": {}})"));
  EXPECT_NE(typo["error"]["message"].get<std::string>().find("scna"), std::string::npos)
      << typo.dump();
  EXPECT_EQ(c.Call(R"({"id": 4, "cmd": "status"})")["state"], "armed");
  EXPECT_TRUE(c.Call(R"({"id": 5, "cmd": "list_results"})")["results"].empty());
}

// The daemon's machine (backend and calibration from its config) wins over the job's: the
// shipped job names a calibration file (out/calib/machine.yaml) this cell need not have, and
// runs on the cell's own. A client cannot name another through `set`: refused by key.
TEST(Jobs, TheDaemonsMachineWinsOverTheJobs) {
  ServerOptions o = Loopback("insitu_jobs_machine");
  o.machine_sets = {"machine.backend=sim",
                    "machine.calibration=" INSITU_SOURCE_DIR "/calib/as_designed.yaml"};
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  const json refused = c.Call(
      RunLine(3, R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.x_start_mm": -3.0, )"
                 R"("scan.x_end_mm": -2.0, "machine.calibration": "no/such/calibration.yaml"})"));
  ASSERT_EQ(refused["ok"], false) << refused.dump();
  EXPECT_NE(refused["error"]["message"].get<std::string>().find("machine.calibration"),
            std::string::npos);
  const json started = c.Call(RunLine(4, kShortScan));
  ASSERT_EQ(started["ok"], true) << started.dump();
  EXPECT_EQ(WaitForJobEnd(c, started["job_id"])["status"], "done");
}

TEST(Jobs, ShutdownNeedsAnAdminClient) {
  ServerOptions o = Loopback("insitu_jobs_admin");
  o.token = "operator-secret";
  o.admin_token = "admin-secret";
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  Client op(server.port());
  const json role = op.Call(R"({"id": 1, "cmd": "auth", "token": "operator-secret"})");
  EXPECT_EQ(role["role"], "operator");
  EXPECT_EQ(op.Call(R"({"id": 2, "cmd": "shutdown"})")["error"]["code"], "forbidden");
  EXPECT_TRUE(Pong(op));  // refused, not closed
  Client admin(server.port());
  EXPECT_EQ(admin.Call(R"({"id": 1, "cmd": "auth", "token": "admin-secret"})")["role"], "admin");
  EXPECT_EQ(admin.Call(R"({"id": 2, "cmd": "shutdown"})")["ok"], true);
  server.WaitForShutdown();  // returns: the shutdown was taken
}

}  // namespace
}  // namespace insitu::daemon
