// insitud: the long-running daemon. Serves the command socket (docs/protocol.md) until a
// client's `shutdown`, SIGTERM or SIGINT; then stops safely and exits 0.
//   insitud --config config/insitud.yaml
// Exit codes: 0 after a clean stop, 2 for a bad config (one line naming file, line and key),
// 1 when the socket cannot be served (address in use).
#include <pthread.h>
#include <signal.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "insitu/calib/calibration.h"
#include "insitu/core/config.h"
#include "insitu/core/log.h"
#include "insitu/daemon/confine.h"
#include "insitu/daemon/server.h"
#include "insitu/hw/cell.h"
#include "insitu/job/job_file.h"

#ifndef INSITU_VERSION
#define INSITU_VERSION "0.0.0"
#endif

namespace {

struct DaemonConfig {
  insitu::daemon::ServerOptions server;
  std::string log_level = "info";
  insitu::hw::MachineConfig machine;  // the machine: section, read as a job's
};

// A YAML value as --set text: scalars as they are (quoted when YAML would read them
// otherwise), sequences as a flow list.
std::string SetText(const insitu::ConfigNode& node) {
  if (node.IsSequence()) {
    std::string out = "[";
    for (size_t i = 0; i < node.size(); ++i) {
      out += (i ? ", " : "") + SetText(node.At(i));
    }
    return out + "]";
  }
  const std::string v = node.AsString().ok() ? *node.AsString() : "";
  if (v.empty() || v.find_first_of(":#[]{},&*!|>'\"%@`") != std::string::npos ||
      v.front() == ' ' || v.back() == ' ') {
    std::string quoted = "\"";
    for (char ch : v) quoted += ch == '"' || ch == '\\' ? std::string("\\") + ch : std::string(1, ch);
    return quoted + "\"";
  }
  return v;
}

// Every entry of a map as "prefix.key=value" (nested maps as dotted keys).
void Flatten(const insitu::ConfigNode& node, const std::string& prefix,
             std::vector<std::string>* out) {
  if (node.IsMap()) {
    for (const std::string& key : node.Keys()) Flatten(node.Child(key), prefix + "." + key, out);
    return;
  }
  out->push_back(prefix + "=" + SetText(node));
}

// A secret given inline or as a file of one line (never both); never logged.
insitu::Status ReadSecret(const std::string& path, const std::string& key,
                          const std::string& file, std::string* secret) {
  if (file.empty()) return insitu::Status::Ok();
  if (!secret->empty()) {
    return insitu::InvalidArgument(path + ": give " + key + " or " + key + "_file, not both");
  }
  std::ifstream f(file);
  if (!f || !std::getline(f, *secret) || secret->empty()) {
    return insitu::NotFound(path + ": " + key + "_file " + file + " cannot be read or is empty");
  }
  return insitu::Status::Ok();
}

// Versioned YAML; unknown keys are warned with their line, bad values refused.
insitu::Result<DaemonConfig> ReadConfig(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(insitu::ConfigNode root, insitu::ConfigNode::LoadFile(path));
  insitu::ConfigReader r(root);
  DaemonConfig c;
  const std::vector<std::string> known{
      "version",        "bind_address",        "port",        "token",
      "token_file",     "admin_token",         "admin_token_file",
      "results_dir",    "jobs_dir",            "read_roots",  "machine",     "queue",
      "max_queued",     "max_line_bytes",      "max_clients", "idle_timeout_s",
      "auth_timeout_s", "max_unauthenticated", "max_clients_per_address",
      "log_level"};
  for (const std::string& key : root.Keys()) {
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      std::fprintf(stderr, "insitud: warning: %s: unknown key, ignored\n",
                   root.Child(key).Where().c_str());
      r.Skip(key);
    }
  }
  int version = 0;
  r.Require("version");
  r.Read("version", &version);
  if (r.ok() && version != 1) r.Fail("version", "this insitud reads config version 1");
  r.Read("bind_address", &c.server.bind_address);
  r.Read("port", &c.server.port);
  r.Read("token", &c.server.token);
  std::string token_file, admin_token_file;
  r.Read("token_file", &token_file);
  r.Read("admin_token", &c.server.admin_token);
  r.Read("admin_token_file", &admin_token_file);
  r.Read("results_dir", &c.server.results_dir);
  r.Read("jobs_dir", &c.server.jobs_dir);
  // The folders jobs may read from: a list of paths.
  const insitu::ConfigNode roots = root.Child("read_roots");
  if (roots.IsDefined()) {
    r.Skip("read_roots");
    bool listed = roots.IsSequence();
    for (size_t i = 0; listed && i < roots.size(); ++i) {
      auto folder_text = roots.At(i).AsString();
      listed = roots.At(i).IsScalar() && folder_text.ok() && !folder_text->empty();
      if (listed) c.server.read_roots.push_back(*folder_text);
    }
    if (!listed) r.Fail("read_roots", "expected a list of folders");
  }
  insitu::job::MachineSpec machine;
  const bool has_machine = r.Has("machine");
  const std::string folder = std::filesystem::absolute(path).parent_path().string();
  if (has_machine) {
    // The same keys and checks as a job's machine: section.
    insitu::job::ReadMachine(r, folder, &machine);
    const auto names = insitu::hw::BackendNames();
    if (r.ok() && std::find(names.begin(), names.end(), machine.config.backend) == names.end()) {
      std::string known;
      for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
      r.Fail("machine", "backend '" + machine.config.backend + "' is not in this build (" + known + ")");
    }
  }
  r.Read("queue", &c.server.queue);
  r.Read("max_queued", &c.server.max_queued);
  int max_line = static_cast<int>(c.server.max_line_bytes);
  r.Read("max_line_bytes", &max_line);
  c.server.max_line_bytes = static_cast<size_t>(std::max(0, max_line));
  r.Read("max_clients", &c.server.max_clients);
  r.Read("idle_timeout_s", &c.server.idle_timeout_s);
  r.Read("auth_timeout_s", &c.server.auth_timeout_s);
  r.Read("max_unauthenticated", &c.server.max_unauthenticated);
  r.Read("max_clients_per_address", &c.server.max_clients_per_address);
  r.ReadEnum("log_level", &c.log_level, {"trace", "debug", "info", "warn", "error", "off"});
  if (r.ok()) r.FailFromValidate(c.server.Validate());
  INSITU_RETURN_IF_ERROR(r.Finish());
  INSITU_RETURN_IF_ERROR(ReadSecret(path, "token", token_file, &c.server.token));
  INSITU_RETURN_IF_ERROR(
      ReadSecret(path, "admin_token", admin_token_file, &c.server.admin_token));
  // A secret where jobs may read would be a job's to quote: refused.
  {
    insitu::daemon::ReadRoots roots;
    roots.folders = c.server.read_roots.empty() ? std::vector<std::string>{c.server.jobs_dir}
                                                : c.server.read_roots;
    for (const auto& [key, file] : {std::pair<const char*, const std::string&>{"token_file", token_file},
                                    {"admin_token_file", admin_token_file}}) {
      if (!file.empty() && insitu::daemon::InsideRoots(file, roots)) {
        return insitu::InvalidArgument(path + ": " + key + ": " + file +
                                       " lies inside the folders jobs may read (jobs_dir, "
                                       "read_roots): keep secrets outside them");
      }
    }
  }
  if (has_machine) {
    // Checked now: a daemon that would fail every job on its calibration does not start.
    const auto calibration = insitu::calib::LoadCalibration(machine.calibration_path);
    if (!calibration.ok()) {
      return calibration.status().Prefixed(path + ": machine.calibration");
    }
    // The daemon's cell replaces a job's machine: section whole (machine={} first): a job
    // cannot add a device to it, not even a simulated one.
    c.server.machine_sets.push_back("machine={}");
    Flatten(root.Child("machine"), "machine", &c.server.machine_sets);
    for (std::string& s : c.server.machine_sets) {
      // Files named relative to this config resolve from its folder, as the jobs' do theirs.
      if (s.rfind("machine.calibration=", 0) == 0) {
        s = "machine.calibration=" + machine.calibration_path;
      } else if (s.rfind("machine.lmc.correction=", 0) == 0) {
        s = "machine.lmc.correction=" + machine.config.lmc.correction_file;
      }
    }
    c.machine = machine.config;
  }
  INSITU_RETURN_IF_ERROR(c.server.Validate().Prefixed(path));
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"insitud: the insitu daemon (command socket, jobs, results)"};
  app.set_version_flag("--version", std::string("insitud ") + INSITU_VERSION);
  std::string config_path;
  app.add_option("--config", config_path, "daemon config (YAML)")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  auto config = ReadConfig(config_path);
  if (!config.ok()) {
    std::fprintf(stderr, "insitud: %s\n", config.status().message().c_str());
    return 2;
  }
  insitu::SetLogLevel(config->log_level);
  {
    // Real devices the machine names are opened once now: a cell whose camera or board cannot
    // be opened does not start serving (devices served by the simulator come up per job).
    const insitu::hw::MachineConfig& m = config->machine;
    if (insitu::hw::IsRealCell(m)) {
      insitu::hw::MachineConfig probe = m;
      for (insitu::hw::Role r : insitu::hw::kRoles) {
        if (!insitu::hw::IsRealDevice(m, r)) insitu::hw::DeviceField(probe, r) = "none";
      }
      // A stage is not opened here: opening homes it (a move nobody armed). Its port must be
      // there; the controller answers when a job opens it.
      if (probe.stage == "grbl") {
        probe.stage = "none";
        std::error_code ec;
        if (!std::filesystem::exists(m.grbl.port, ec)) {
          std::fprintf(stderr, "insitud: %s: machine.grbl.port: %s does not exist\n",
                       config_path.c_str(), m.grbl.port.c_str());
          return 1;
        }
      }
      const auto opened = insitu::hw::CreateMachine(probe);
      if (!opened.ok()) {
        std::fprintf(stderr, "insitud: %s: machine: %s\n", config_path.c_str(),
                     opened.status().message().c_str());
        return 1;
      }
    }
  }
  // SIGTERM and SIGINT are blocked in every thread (the server's inherit the mask) and taken
  // by one thread with sigwait: no work in a signal handler.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  insitu::daemon::Server server(config->server);
  const insitu::Status started = server.Start();
  if (!started.ok()) {
    std::fprintf(stderr, "insitud: %s\n", started.message().c_str());
    return started.code() == insitu::StatusCode::kInvalidArgument ? 2 : 1;
  }
  std::printf("insitud: listening on %s:%d\n", config->server.bind_address.c_str(), server.port());
  std::fflush(stdout);
  std::thread signals([&] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    insitu::Logger("daemon")->info("signal {}: stopping", sig);
    server.Stop();
  });
  server.WaitForShutdown();  // a client's shutdown, or the signal thread's Stop()
  server.Stop();
  pthread_kill(signals.native_handle(), SIGTERM);  // wakes the signal thread if still waiting
  signals.join();
  insitu::Logger("daemon")->info("stopped");
  return 0;
}
