// insitud's command socket: a TCP server speaking the JSON-lines protocol (protocol.h) to many
// clients at once. Every line a client sends is parsed and checked against the command table
// before a handler sees it; a malformed line gets an error reply and the connection goes on;
// a line over the limit, or a wrong token, closes that connection only. With a token
// configured, a connection's first request must be `auth` (the token is never logged).
// Clients that `subscribe` receive an event for every machine-state change and for every job
// that starts or ends.
//
// Jobs: `run` takes the same job files the CLI runs (a path, relative to jobs_dir, or the job
// itself as an object) on an armed machine, one at a time (a further run is refused, or queued
// when `queue` is set); each job writes its report and artifacts into its own folder of the
// results store, and subscribers get its progress. `cancel` stops it (scans between lines, a
// marking list within one head tick with the laser off; the head disarmed on every way out);
// `result` and `list_results` read the store, which survives restarts.
//
// Roles: with `admin_token` set, only a client that authenticated with it may `shutdown`; with
// no token at all every client may (a loopback-only daemon). asio stays in server.cc.
//
// Limits: with a `token`, a connection is unauthenticated until its `auth` succeeds. At most
// `max_unauthenticated` connections wait so (a further one is closed at once with
// `too_many_clients`), each for at most `auth_timeout_s` from its accept (then closed with
// `auth_timeout`), and they never take one of the `max_clients` slots: a successful `auth`
// moves the connection out of that pool into a slot (refused with `too_many_clients` when all
// are taken). Without a token every connection takes a slot at once. With a token or an
// admin token, one peer address holds at most `max_clients_per_address` connections,
// authenticated or not; a daemon with no token at all trusts its peers (any may shut it down)
// and has only `max_clients`.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/daemon/machine_state.h"
#include "insitu/daemon/protocol.h"

namespace insitu::daemon {

struct ServerOptions {
  std::string bind_address = "127.0.0.1";
  int port = 7450;    // 0: any free port (tests)
  std::string token;        // empty: no authentication
  std::string admin_token;  // empty: shutdown only when no token is set either
  size_t max_line_bytes = kDefaultMaxLineBytes;
  int max_clients = 256;          // beyond: the connection is closed with an error line
  double idle_timeout_s = 300.0;  // a client silent this long (or stalled mid-line) is closed
  // With a token: the time from accept to a successful `auth` (then closed with an error
  // line), and how many connections may wait for theirs, outside the max_clients slots.
  double auth_timeout_s = 5.0;
  int max_unauthenticated = 16;
  // Connections from one peer IP address, authenticated or not (with a token or admin token).
  int max_clients_per_address = 32;
  std::string results_dir = "insitu-results";
  std::string jobs_dir = ".";  // relative job paths and inline jobs' relative paths
  // The folders a job may read files from (patterns, worlds, calibrations, tables), besides
  // the files the cell names (machine_sets). Empty: jobs_dir only.
  std::vector<std::string> read_roots;
  // The cell this daemon drives, as overrides applied to every job after the client's own
  // (insitud's `machine:` section): "machine={}" first, so the job's machine: section is
  // replaced whole, then each "machine.key=value". With a cell, a client's set may not name
  // machine.* keys. Empty: each job runs on its own machine: section.
  std::vector<std::string> machine_sets;
  bool queue = false;          // a run while a job runs: queued (true) or refused
  int max_queued = 8;

  Status Validate() const;
};

class Server {
 public:
  explicit Server(ServerOptions options);
  ~Server();
  Server(const Server&) = delete;  // owns a listening socket and its threads
  Server& operator=(const Server&) = delete;

  // Opens the results store, binds and starts serving on a background thread. Errors:
  // invalid_argument for bad options; not_found for a results folder that cannot be made;
  // device_error when the address cannot be bound (in use, not local).
  Status Start();
  // The bound port (after Start; the real one when options.port was 0).
  int port() const;
  // Cancels a running job and waits for it, stops accepting, closes every connection, joins
  // the threads. Idempotent.
  void Stop();
  // Blocks until a client's `shutdown` or Stop().
  void WaitForShutdown();

  StateMachine& state();
  int connected_clients() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::daemon
