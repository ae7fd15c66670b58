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
#include <fstream>
#include <string>
#include <thread>

#include "insitu/core/config.h"
#include "insitu/core/log.h"
#include "insitu/daemon/server.h"

#ifndef INSITU_VERSION
#define INSITU_VERSION "0.0.0"
#endif

namespace {

struct DaemonConfig {
  insitu::daemon::ServerOptions server;
  std::string log_level = "info";
};

// Versioned YAML; unknown keys are warned with their line, bad values refused.
insitu::Result<DaemonConfig> ReadConfig(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(insitu::ConfigNode root, insitu::ConfigNode::LoadFile(path));
  insitu::ConfigReader r(root);
  DaemonConfig c;
  const std::vector<std::string> known{
      "version",  "bind_address",   "port",        "token",          "token_file", "results_dir",
      "jobs_dir", "max_line_bytes", "max_clients", "idle_timeout_s", "log_level"};
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
  std::string token_file;
  r.Read("token_file", &token_file);
  r.Read("results_dir", &c.server.results_dir);
  r.Read("jobs_dir", &c.server.jobs_dir);
  int max_line = static_cast<int>(c.server.max_line_bytes);
  r.Read("max_line_bytes", &max_line);
  c.server.max_line_bytes = static_cast<size_t>(std::max(0, max_line));
  r.Read("max_clients", &c.server.max_clients);
  r.Read("idle_timeout_s", &c.server.idle_timeout_s);
  r.ReadEnum("log_level", &c.log_level, {"trace", "debug", "info", "warn", "error", "off"});
  if (r.ok()) r.FailFromValidate(c.server.Validate());
  INSITU_RETURN_IF_ERROR(r.Finish());
  if (!token_file.empty()) {
    if (!c.server.token.empty()) {
      return insitu::InvalidArgument(path + ": give token or token_file, not both");
    }
    std::ifstream f(token_file);
    if (!f || !std::getline(f, c.server.token) || c.server.token.empty()) {
      return insitu::NotFound(path + ": token_file " + token_file + " cannot be read or is empty");
    }
  }
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
