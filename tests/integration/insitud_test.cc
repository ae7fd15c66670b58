// insitud as a process: started with a config on a free loopback port, it answers ping,
// exits 0 on a client's shutdown and on SIGTERM, and refuses a bad config with one line and
// exit code 2.
#define ASIO_STANDALONE
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <asio.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace {

namespace fs = std::filesystem;

struct Daemon {
  pid_t pid = -1;
  int port = 0;
};

// Starts insitud with `config_text`; reads the port from its "listening on" line.
Daemon Start(const std::string& config_text) {
  const fs::path cfg = fs::temp_directory_path() / "insitud_test.yaml";
  std::ofstream(cfg) << config_text;
  int out[2];
  EXPECT_EQ(pipe(out), 0);
  Daemon d;
  d.pid = fork();
  if (d.pid == 0) {
    dup2(out[1], STDOUT_FILENO);
    close(out[0]);
    execl(INSITUD_BIN, INSITUD_BIN, "--config", cfg.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  close(out[1]);
  FILE* f = fdopen(out[0], "r");
  char line[256] = {0};
  if (fgets(line, sizeof line, f) != nullptr) {
    const std::string s(line);
    const auto colon = s.rfind(':');
    if (s.find("listening on") != std::string::npos && colon != std::string::npos) {
      d.port = std::stoi(s.substr(colon + 1));
    }
  }
  fclose(f);
  return d;
}

int ExitCode(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

nlohmann::json Call(asio::ip::tcp::socket& s, const std::string& line) {
  asio::write(s, asio::buffer(line + "\n"));
  asio::streambuf buf;
  asio::error_code ec;
  const size_t n = asio::read_until(s, buf, '\n', ec);
  if (ec) return nullptr;
  return nlohmann::json::parse(
      std::string(asio::buffers_begin(buf.data()), asio::buffers_begin(buf.data()) + n - 1),
      nullptr, false);
}

TEST(Insitud, ServesUntilShutdownOrSigterm) {
  {
    const Daemon d = Start("version: 1\nport: 0\n");
    ASSERT_GT(d.port, 0);
    asio::io_context io;
    asio::ip::tcp::socket s(io);
    s.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(d.port)});
    EXPECT_EQ(Call(s, R"({"id": 1, "cmd": "ping"})")["pong"], true);
    EXPECT_EQ(Call(s, R"({"id": 2, "cmd": "shutdown"})")["ok"], true);
    EXPECT_EQ(ExitCode(d.pid), 0);
  }
  {
    const Daemon d = Start("version: 1\nport: 0\n");
    ASSERT_GT(d.port, 0);
    kill(d.pid, SIGTERM);
    EXPECT_EQ(ExitCode(d.pid), 0);
  }
}

// The example client in docs/ runs a job against insitud and follows its progress to the end.
TEST(Insitud, TheExampleClientRunsAJobAndFollowsIt) {
  const Daemon d = Start("version: 1\nport: 0\nresults_dir: " +
                         (fs::temp_directory_path() / "insitud_client_results").string() + "\n");
  ASSERT_GT(d.port, 0);
  const std::string command = "python3 docs/insitu_client.py config/jobs/scan_step_gauge.yaml"
                              " --port " + std::to_string(d.port) +
                              " --set scan.x_start_mm=-3 --set scan.x_end_mm=-2 2>&1";
  FILE* p = popen(command.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[512];
  while (fgets(buf, sizeof buf, p) != nullptr) out += buf;
  EXPECT_EQ(pclose(p), 0) << out;
  EXPECT_NE(out.find("scan: 3/3 lines (100%)"), std::string::npos) << out;
  EXPECT_NE(out.find("job done"), std::string::npos) << out;
  EXPECT_NE(out.find("points = "), std::string::npos) << out;
  kill(d.pid, SIGTERM);
  EXPECT_EQ(ExitCode(d.pid), 0);
}

// SIGTERM during a job: the job is cancelled and saved, insitud exits 0. SIGKILL during a job:
// after the restart the job is listed interrupted, never done.
TEST(Insitud, AJobSurvivesAsCancelledOrInterruptedAcrossRestarts) {
  const std::string results = (fs::temp_directory_path() / "insitud_restart_results").string();
  fs::remove_all(results);
  const std::string config = "version: 1\nport: 0\nresults_dir: " + results + "\n";
  const auto start_job = [&](const Daemon& d) {
    asio::io_context io;
    asio::ip::tcp::socket s(io);
    s.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(d.port)});
    EXPECT_EQ(Call(s, R"({"id": 1, "cmd": "arm"})")["ok"], true);
    // The whole step-gauge scan: many seconds.
    const auto r = Call(s, R"({"id": 2, "cmd": "run", "job": "config/jobs/scan_step_gauge.yaml"})");
    EXPECT_EQ(r["ok"], true) << r.dump();
    return r.value("job_id", std::string());
  };
  const auto list = [&]() {
    const Daemon d = Start(config);
    asio::io_context io;
    asio::ip::tcp::socket s(io);
    s.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(d.port)});
    const auto r = Call(s, R"({"id": 1, "cmd": "list_results"})");
    kill(d.pid, SIGTERM);
    EXPECT_EQ(ExitCode(d.pid), 0);
    return r["results"];
  };
  {
    const Daemon d = Start(config);
    ASSERT_GT(d.port, 0);
    const std::string id = start_job(d);
    usleep(500 * 1000);
    kill(d.pid, SIGTERM);
    EXPECT_EQ(ExitCode(d.pid), 0);
    const auto results = list();
    ASSERT_EQ(results.size(), 1u);
    EXPECT_EQ(results[0]["job_id"], id);
    EXPECT_EQ(results[0]["status"], "cancelled");
  }
  {
    const Daemon d = Start(config);
    ASSERT_GT(d.port, 0);
    const std::string id = start_job(d);
    usleep(500 * 1000);
    kill(d.pid, SIGKILL);
    ExitCode(d.pid);
    const auto results = list();
    ASSERT_EQ(results.size(), 2u);
    EXPECT_EQ(results[0]["job_id"], id);
    EXPECT_EQ(results[0]["status"], "interrupted");
    EXPECT_EQ(results[1]["status"], "cancelled");  // the first one, as it was
  }
}

TEST(Insitud, ABadConfigIsOneLineAndExit2) {
  for (const char* config : {
           "version: 1\nport: 70000\n",
           "version: 1\nport: 0\nmachine:\n  backend: teleport\n",  // no such backend
           "version: 1\nport: 0\nmachine:\n  backend: sim\n  calibration: calib/none.yaml\n",
           "version: 1\nport: 0\nqueue: true\nmax_queued: 0\n",
           "version: 1\nport: 0\ntoken: same\nadmin_token: same\n",
           "version: 1\nport: 0\nauth_timeout_s: 0\n",
           "version: 1\nport: 0\nmax_unauthenticated: 0\n",
           "version: 1\nport: 0\nmax_clients_per_address: -1\n",
       }) {
    const Daemon d = Start(config);
    EXPECT_EQ(d.port, 0) << config;
    EXPECT_EQ(ExitCode(d.pid), 2) << config;
  }
}

// A cell whose board cannot be opened does not start serving: exit 1, nothing listens.
TEST(Insitud, AMachineWhoseDeviceIsMissingDoesNotStart) {
  const Daemon d = Start(
      "version: 1\nport: 0\nmachine:\n  backend: sim\n  calibration: " INSITU_SOURCE_DIR
      "/calib/as_designed.yaml\n  scanner: lmc\n  lmc:\n    transport: usb\n    pid: 0x0001\n");
  EXPECT_EQ(d.port, 0);
  EXPECT_EQ(ExitCode(d.pid), 1);
}

// The shipped example's keys, with the cell's machine, a queue and an admin token: only the
// admin client may stop it.
TEST(Insitud, TheDaemonsMachineQueueAndAdmin) {
  const Daemon d = Start(
      "version: 1\nport: 0\nmachine:\n  backend: sim\n  calibration: " INSITU_SOURCE_DIR
      "/calib/as_designed.yaml\nqueue: true\nmax_queued: 4\ntoken: op\nadmin_token: boss\n");
  ASSERT_GT(d.port, 0);
  asio::io_context io;
  asio::ip::tcp::socket op(io), admin(io);
  op.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(d.port)});
  EXPECT_EQ(Call(op, R"({"id": 1, "cmd": "auth", "token": "op"})")["role"], "operator");
  EXPECT_EQ(Call(op, R"({"id": 2, "cmd": "shutdown"})")["error"]["code"], "forbidden");
  admin.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(d.port)});
  EXPECT_EQ(Call(admin, R"({"id": 1, "cmd": "auth", "token": "boss"})")["role"], "admin");
  EXPECT_EQ(Call(admin, R"({"id": 2, "cmd": "shutdown"})")["ok"], true);
  EXPECT_EQ(ExitCode(d.pid), 0);
}

}  // namespace
