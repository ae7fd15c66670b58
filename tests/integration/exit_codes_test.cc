// insitu's exit codes, on the process as a shell or a cell's PLC sees them: 0 done, 1 a device
// failing while the job runs, 2 bad input, 130 interrupted by SIGINT mid-job.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "support/grbl_emulator.h"

namespace {

namespace fs = std::filesystem;

fs::path Dir() { return fs::temp_directory_path() / "insitu_exit_codes_test"; }

std::string Job(const std::string& name) {
  return std::string(INSITU_SOURCE_DIR) + "/config/jobs/" + name;
}

// Runs insitu with `args` (output to /dev/null, `input` on its standard input, then closed);
// after `interrupt_after_s` (>= 0) sends SIGINT. Returns the exit code, or -1 when it did not
// exit normally.
int Insitu(const std::vector<std::string>& args, double interrupt_after_s = -1.0,
           const std::string& input = "") {
  int in[2];
  if (pipe(in) != 0) return -1;
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(in[0], STDIN_FILENO);
    close(in[0]);
    close(in[1]);
    std::vector<char*> argv{const_cast<char*>(INSITU_BIN)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    freopen("/dev/null", "w", stdout);
    freopen("/dev/null", "w", stderr);
    execv(INSITU_BIN, argv.data());
    _exit(127);
  }
  close(in[0]);
  if (!input.empty() && write(in[1], input.data(), input.size()) < 0) kill(pid, SIGKILL);
  close(in[1]);
  if (interrupt_after_s >= 0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(interrupt_after_s));
    kill(pid, SIGINT);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(ExitCodes, DoneFailedBadInputInterrupted) {
  fs::remove_all(Dir());
  const std::string out = (Dir() / "out").string();
  // 0: the profiler's mounting calibrated on the block (a second of simulation).
  EXPECT_EQ(Insitu({"run", Job("calibrate_profiler.yaml"), "--out", out, "--set",
                    "output.mount_file=" + (Dir() / "mount.yaml").string()}),
            0);
  // 1: the profiler stops sending while the block is scanned.
  EXPECT_EQ(Insitu({"run", Job("calibrate_profiler.yaml"), "--out", out, "--set",
                    "world.faults.profiler_stop_at_profile=3", "--set",
                    "output.mount_file=" + (Dir() / "mount_stopped.yaml").string()}),
            1);
  // 2: a value out of its range, a job file that is not there, a command line it refuses.
  EXPECT_EQ(Insitu({"run", Job("calibrate_profiler.yaml"), "--out", out, "--set",
                    "profiler.block.base_mm=-1"}),
            2);
  EXPECT_EQ(Insitu({"run", (Dir() / "no_such_job.yaml").string()}), 2);
  EXPECT_EQ(Insitu({"run"}), 2);
  // 130: the calibrate job (about 20 s of board views) interrupted two seconds in (the handler
  // is set before the job file loads, so an early interrupt stops it at its first step).
  const fs::path previous = Dir() / "machine.yaml";
  std::ofstream(previous) << "# the cell's previous calibration\n";
  EXPECT_EQ(Insitu({"run", Job("calibrate.yaml"), "--out", (Dir() / "calibrate").string(), "--set",
                    "output.calibration=" + previous.string()},
                   2.0),
            130);
  // Interrupted, it kept the previous calibration as it was.
  std::ifstream kept(previous);
  std::string line;
  std::getline(kept, line);
  EXPECT_EQ(line, "# the cell's previous calibration");
}

// A real stage (a GRBL controller's emulator on a pseudo-terminal) in an otherwise simulated
// dry run: its hard-limit alarm on the calibrate job's first move faults the job, exit code 1.
TEST(ExitCodes, ARealStagesAlarmFaultsTheJob) {
  const fs::path dir = Dir() / "grbl";
  fs::remove_all(dir);
  insitu::testing::GrblEmulatorOptions fast;
  fast.time_scale = 0.05;
  insitu::testing::GrblEmulator emulator(fast);
  emulator.SetLimitSwitchAt(-30.0);  // between homing (-1) and the board's height (-45)
  const std::vector<std::string> run = {
      "run", Job("calibrate.yaml"), "--out", (dir / "out").string(),
      "--set", "output.calibration=" + (dir / "cal.yaml").string(),
      "--set", "machine.stage=grbl", "--set", "machine.grbl.port=" + emulator.port(),
      "--set", "machine.grbl.min_z_mm=-20", "--set", "machine.grbl.max_z_mm=20",
      "--set", "machine.grbl.machine_zero_mm=-25", "--set", "machine.grbl.banner_wait_s=0.05",
      "--set", "machine.scanner=sim", "--set", "machine.camera=sim",
      "--set", "machine.operator=sim"};
  EXPECT_EQ(Insitu(run), 1);
  EXPECT_NEAR(emulator.machine_z_mm(), -30.0, 0.5);  // stopped at the switch
  std::ifstream report(dir / "out" / "report.json");
  std::stringstream text;
  text << report.rdbuf();
  EXPECT_NE(text.str().find("ALARM:1"), std::string::npos) << text.str();
  EXPECT_NE(text.str().find("dry run: the scan head is simulated"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "cal.yaml"));
}

// A cell whose operator is a person asks at the terminal: "abort" there, or no one to answer
// (standard input closed), ends the job as interrupted, its calibration untouched.
TEST(ExitCodes, TheOperatorAtTheTerminalCanStopTheJob) {
  const fs::path dir = Dir() / "operator";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::vector<std::string> run = {
      "run", Job("calibrate.yaml"), "--out", (dir / "out").string(), "--set",
      "machine.operator=person", "--set", "output.calibration=" + (dir / "cal.yaml").string()};
  EXPECT_EQ(Insitu(run, -1.0, "\nabort\n"), 130);  // one view placed, then aborted
  EXPECT_EQ(Insitu(run, -1.0, "no\nstop\n"), 130);  // neither confirms: asked again, then EOF
  EXPECT_EQ(Insitu(run, -1.0, ""), 130);
  EXPECT_FALSE(fs::exists(dir / "cal.yaml"));
}

}  // namespace
