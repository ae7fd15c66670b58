// insitud's command socket: a TCP server speaking the JSON-lines protocol (protocol.h) to many
// clients at once. Every line a client sends is parsed and checked against the command table
// before a handler sees it; a malformed line gets an error reply and the connection goes on;
// a line over the limit, or a wrong token, closes that connection only. With a token
// configured, a connection's first request must be `auth` (the token is never logged).
// Clients that `subscribe` receive an event for every machine-state change.
//
// This increment serves auth, ping, status, arm, disarm, subscribe and shutdown; the
// job-running commands (run, cancel, result, list_results) reply not_implemented until the
// job runner is wired in. asio stays inside server.cc.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "insitu/core/status.h"
#include "insitu/daemon/machine_state.h"
#include "insitu/daemon/protocol.h"

namespace insitu::daemon {

struct ServerOptions {
  std::string bind_address = "127.0.0.1";
  int port = 7450;    // 0: any free port (tests)
  std::string token;  // empty: no authentication
  size_t max_line_bytes = kDefaultMaxLineBytes;
  int max_clients = 256;          // beyond: the connection is closed with an error line
  double idle_timeout_s = 300.0;  // a client silent this long (or stalled mid-line) is closed

  Status Validate() const;
};

class Server {
 public:
  explicit Server(ServerOptions options);
  ~Server();
  Server(const Server&) = delete;  // owns a listening socket and its threads
  Server& operator=(const Server&) = delete;

  // Binds and starts serving on a background thread. Errors: invalid_argument for bad
  // options; device_error when the address cannot be bound (in use, not local).
  Status Start();
  // The bound port (after Start; the real one when options.port was 0).
  int port() const;
  // Stops accepting, closes every connection, joins the thread. Idempotent.
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
