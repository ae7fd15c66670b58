#include "insitu/daemon/server.h"

#include "insitu/daemon/confine.h"

#define ASIO_STANDALONE
#include <algorithm>
#include <asio.hpp>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "daemon/job_queue.h"
#include "insitu/core/log.h"
#include "insitu/daemon/results.h"
#include "insitu/job/job_file.h"
#include "insitu/job/runner.h"

namespace insitu::daemon {
namespace {

// Compares every byte whatever the first difference (the token is a secret).
bool EqualConstantTime(const std::string& a, const std::string& b) {
  unsigned diff = a.size() != b.size();
  const size_t n = std::max(a.size(), b.size());
  for (size_t i = 0; i < n; ++i) {
    diff |= static_cast<unsigned char>(i < a.size() ? a[i] : 0) ^
            static_cast<unsigned char>(i < b.size() ? b[i] : 0);
  }
  return diff == 0;
}

}  // namespace

Status ServerOptions::Validate() const {
  if (port < 0 || port > 65535) return InvalidArgument("port must be in 0..65535");
  if (max_line_bytes < 64) return InvalidArgument("max_line_bytes must be >= 64");
  if (max_clients < 1) return InvalidArgument("max_clients must be >= 1");
  if (!(idle_timeout_s > 0)) return InvalidArgument("idle_timeout_s must be > 0");
  if (!(auth_timeout_s > 0 && auth_timeout_s <= 3600)) {
    return InvalidArgument("auth_timeout_s must be in (0, 3600] seconds");
  }
  if (max_unauthenticated < 1 || max_unauthenticated > 100000) {
    return InvalidArgument("max_unauthenticated must be in 1..100000");
  }
  if (max_clients_per_address < 1) return InvalidArgument("max_clients_per_address must be >= 1");
  if (max_queued < 1 || max_queued > 1000) return InvalidArgument("max_queued must be in 1..1000");
  if (!admin_token.empty() && admin_token == token) {
    return InvalidArgument("admin_token must differ from token");
  }
  asio::error_code ec;
  asio::ip::make_address(bind_address, ec);
  if (ec) return InvalidArgument("bind_address '" + bind_address + "' is not an IP address");
  for (const std::string& root : read_roots) {
    std::error_code ec_root;
    if (!std::filesystem::is_directory(root, ec_root)) {
      return InvalidArgument("read_roots: '" + root + "' is not a folder");
    }
  }
  return Status::Ok();
}

struct Server::Impl {
  class Session;

  explicit Impl(ServerOptions o) : options(std::move(o)), acceptor(io) {}

  ServerOptions options;
  asio::io_context io;
  asio::ip::tcp::acceptor acceptor;
  asio::steady_timer accept_retry{io};
  std::thread thread;
  std::set<std::shared_ptr<Session>> sessions;  // touched on the io thread only
  std::atomic<int> clients{0};  // every open connection, refused ones until their line is sent
  // The limits (header, "Limits"); io thread only.
  int unauthenticated = 0;  // in the pool: a token is configured and their auth has not come
  int authenticated = 0;    // in one of the max_clients slots
  std::map<std::string, int> per_address;  // with a token or admin token: peer IP -> connections
  // With a token: peer IP -> its connections waiting to authenticate. One address may hold a
  // quarter of the pool at most, so a flood from it cannot keep others from authenticating.
  std::map<std::string, int> unauthenticated_per_address;
  StateMachine state;
  int bound_port = 0;
  std::unique_ptr<ResultsStore> store;
  std::unique_ptr<JobQueue> jobs;  // after store: it records into it

  std::string Run(const Request& r);
  std::string Cancel(const Request& r);
  std::string ResultOf(const Request& r);
  std::string ListResults(const Request& r);
  std::mutex shutdown_mutex;
  std::condition_variable shutdown_cv;
  bool shutdown = false;
  std::atomic<bool> running{false};
  std::shared_ptr<spdlog::logger> log = Logger("daemon");

  void Accept();
  void Broadcast(const std::string& line);  // io thread
  void RequestShutdown() {
    std::lock_guard<std::mutex> lock(shutdown_mutex);
    shutdown = true;
    shutdown_cv.notify_all();
  }
};

class Server::Impl::Session : public std::enable_shared_from_this<Session> {
 public:
  // Replies and events waiting for a client that does not read: beyond, it is closed.
  static constexpr size_t kMaxQueuedLines = 1000;

  Session(Impl* server, asio::ip::tcp::socket socket)
      : server_(server),
        socket_(std::move(socket)),
        buffer_(server->options.max_line_bytes + 1),
        timer_(server->io),
        auth_timer_(server->io) {
    asio::error_code ec;
    const auto ep = socket_.remote_endpoint(ec);
    if (!ec) {
      asio::ip::address a = ep.address();
      // An IPv4 peer of a dual-stack socket is the same peer as over IPv4.
      if (a.is_v6() && a.to_v6().is_v4_mapped()) {
        a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
      }
      address_ = a.to_string();
    }
    peer_ = ec ? std::string("?") : address_ + ":" + std::to_string(ep.port());
  }

  // Takes a place for this new connection (the unauthenticated pool with a token, else a
  // slot) and counts it against its address. Returns why it is refused, or "" when admitted.
  std::string Admit() {
    const ServerOptions& o = server_->options;
    const bool per_address = !o.token.empty() || !o.admin_token.empty();
    if (per_address) {
      const auto it = server_->per_address.find(address_);
      if (it != server_->per_address.end() && it->second >= o.max_clients_per_address) {
        return "one address holds " + std::to_string(o.max_clients_per_address) +
               " connections at most";
      }
    }
    if (!o.token.empty()) {
      const int share = std::max(1, o.max_unauthenticated / 4);
      const auto mine = server_->unauthenticated_per_address.find(address_);
      if (mine != server_->unauthenticated_per_address.end() && mine->second >= share) {
        return "one address may wait to authenticate on " + std::to_string(share) +
               " connections at most";
      }
      if (server_->unauthenticated >= o.max_unauthenticated) {
        return std::to_string(o.max_unauthenticated) +
               " connections are already waiting to authenticate; try again shortly";
      }
      ++server_->unauthenticated;
      ++server_->unauthenticated_per_address[address_];
      slot_ = Slot::kUnauthenticated;
    } else {
      if (server_->authenticated >= o.max_clients) return TooManyClients();
      ++server_->authenticated;
      slot_ = Slot::kClient;
    }
    if (per_address) {
      ++server_->per_address[address_];
      address_counted_ = true;
    }
    return "";
  }

  void Begin() {
    ArmTimer();
    if (slot_ == Slot::kUnauthenticated) {
      ArmAuthTimer(std::chrono::milliseconds(
          static_cast<int64_t>(server_->options.auth_timeout_s * 1000.0)));
    }
    Read();
  }

  const std::string& peer() const { return peer_; }

  void Send(const std::string& line) {
    if (closed_) return;
    if (out_.size() >= kMaxQueuedLines) {
      // The client has stopped reading: its lines would pile up without end.
      server_->log->warn("closing {}: {} lines unread", peer_, out_.size());
      Close();
      return;
    }
    const bool idle = out_.empty();
    out_.push_back(line);
    if (idle) WriteNext();
  }

  // Sends the last line, then closes (auth failures, over-long lines).
  void SendAndClose(const std::string& line) {
    closing_ = true;
    Send(line);
  }

  void Close() {
    if (closed_) return;
    closed_ = true;
    asio::error_code ec;
    timer_.cancel();
    auth_timer_.cancel();
    socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
    socket_.close(ec);
    Release();
    server_->clients--;
    server_->sessions.erase(shared_from_this());
  }

  bool subscribed() const { return subscribed_; }

 private:
  enum class Slot { kNone, kUnauthenticated, kClient };

  std::string TooManyClients() const {
    return "the daemon serves " + std::to_string(server_->options.max_clients) +
           " clients at most";
  }

  // Out of the unauthenticated pool into a slot, after a good token. False when every slot is
  // taken (the connection is then refused).
  bool Promote() {
    if (slot_ != Slot::kUnauthenticated) return true;
    if (server_->authenticated >= server_->options.max_clients) return false;
    --server_->unauthenticated;
    LeaveUnauthenticated();
    ++server_->authenticated;
    slot_ = Slot::kClient;
    auth_timer_.cancel();
    return true;
  }

  void LeaveUnauthenticated() {
    const auto it = server_->unauthenticated_per_address.find(address_);
    if (it != server_->unauthenticated_per_address.end() && --it->second == 0) {
      server_->unauthenticated_per_address.erase(it);
    }
  }

  void Release() {
    if (slot_ == Slot::kUnauthenticated) {
      --server_->unauthenticated;
      LeaveUnauthenticated();
    }
    if (slot_ == Slot::kClient) --server_->authenticated;
    slot_ = Slot::kNone;
    if (address_counted_) {
      const auto it = server_->per_address.find(address_);
      if (--it->second == 0) server_->per_address.erase(it);
      address_counted_ = false;
    }
  }

  // Fixed from the accept, not re-armed by lines: junk lines do not buy time. After the error
  // line, a short grace for it to be written; a peer that does not take it is closed anyway,
  // so a pool place is held auth_timeout_s + 1 s at most.
  void ArmAuthTimer(std::chrono::milliseconds after) {
    auth_timer_.expires_after(after);
    auth_timer_.async_wait([self = shared_from_this()](const asio::error_code& ec) {
      if (ec || self->closed_ || self->slot_ != Slot::kUnauthenticated) return;
      if (self->closing_ || !self->out_.empty()) {
        self->Close();
        return;
      }
      self->server_->log->debug("closing {}: no auth within {} s", self->peer_,
                                self->server_->options.auth_timeout_s);
      self->SendAndClose(ReplyError(nullptr, errc::kAuthTimeout,
                                    "no auth within " +
                                        FormatSeconds(self->server_->options.auth_timeout_s) +
                                        " s of connecting; closing the connection"));
      self->ArmAuthTimer(std::chrono::seconds(1));
    });
  }

  static std::string FormatSeconds(double s) {
    std::ostringstream out;
    out << s;
    return out.str();
  }

  void ArmTimer() {
    timer_.expires_after(
        std::chrono::milliseconds(static_cast<int64_t>(server_->options.idle_timeout_s * 1000.0)));
    timer_.async_wait([self = shared_from_this()](const asio::error_code& ec) {
      if (ec) return;  // re-armed or cancelled
      self->server_->log->info("closing {}: idle for {} s", self->peer_,
                               self->server_->options.idle_timeout_s);
      if (!self->out_.empty()) {
        self->Close();  // not reading either: a last line would never be taken
        return;
      }
      self->SendAndClose(ReplyError(nullptr, errc::kIdleTimeout, "no complete line for too long"));
    });
  }

  void Read() {
    asio::async_read_until(
        socket_, buffer_, '\n', [self = shared_from_this()](const asio::error_code& ec, size_t n) {
          // Closing: its last line is on the way, and nothing it says now counts (an auth after
          // its deadline).
          if (self->closed_ || self->closing_) return;
          if (ec == asio::error::not_found) {
            // The buffer filled without a newline: the line is over the limit.
            self->SendAndClose(
                ReplyError(nullptr, errc::kLineTooLong,
                           "a line over " + std::to_string(self->server_->options.max_line_bytes) +
                               " bytes; closing the connection"));
            return;
          }
          if (ec) {
            self->Close();  // the client went away (or the server stops)
            return;
          }
          std::string line(asio::buffers_begin(self->buffer_.data()),
                           asio::buffers_begin(self->buffer_.data()) + n - 1);
          self->buffer_.consume(n);
          self->ArmTimer();
          self->Handle(line);
          if (!self->closing_ && !self->closed_) self->Read();
        });
  }

  void WriteNext() {
    asio::async_write(socket_, asio::buffer(out_.front()),
                      [self = shared_from_this()](const asio::error_code& ec, size_t) {
                        if (self->closed_) return;
                        if (ec) {
                          self->Close();
                          return;
                        }
                        self->out_.pop_front();
                        if (!self->out_.empty()) {
                          self->WriteNext();
                        } else if (self->closing_) {
                          self->Close();
                        }
                      });
  }

  void Handle(const std::string& line) {
    const ParsedLine p = ParseRequest(line, server_->options.max_line_bytes);
    if (!p.ok) {
      Send(ReplyError(p.error.id, p.error.code, p.error.message));
      return;
    }
    const Request& r = p.request;
    const ServerOptions& o = server_->options;
    if (!o.token.empty() && !authed_ && r.cmd != "auth") {
      server_->log->warn("refused {}: '{}' before auth", peer_, r.cmd.substr(0, 32));
      SendAndClose(
          ReplyError(r.id, errc::kUnauthorized, "authenticate first: {\"cmd\": \"auth\", ...}"));
      return;
    }
    if (r.cmd == "auth" && (!o.token.empty() || !o.admin_token.empty())) {
      const std::string given = r.body.contains("token") && r.body["token"].is_string()
                                    ? r.body["token"].get<std::string>()
                                    : std::string();
      // Both compared, whichever matches: the time taken tells nothing.
      const bool admin = !o.admin_token.empty() && EqualConstantTime(given, o.admin_token);
      const bool operator_ = !o.token.empty() && EqualConstantTime(given, o.token);
      if (!admin && !operator_) {
        server_->log->warn("refused {}: wrong token", peer_);  // never the token itself
        SendAndClose(ReplyError(r.id, errc::kUnauthorized, "wrong token"));
        return;
      }
      if (!Promote()) {
        server_->log->warn("refused {}: every client slot is taken", peer_);
        SendAndClose(ReplyError(r.id, errc::kTooManyClients, TooManyClients()));
        return;
      }
      authed_ = true;
      admin_ = admin;
      server_->log->info("{} authenticated as {}", peer_, admin ? "admin" : "operator");
      Send(ReplyOk(r.id, {{"role", admin ? "admin" : "operator"}}));
      return;
    }
    if (const auto error = CheckRequest(r)) {
      Send(ReplyError(error->id, error->code, error->message));
      return;
    }
    const CommandSpec* spec = FindCommand(r.cmd);
    const bool open_daemon = o.token.empty() && o.admin_token.empty();
    if (spec->admin && !admin_ && !open_daemon) {
      server_->log->warn("refused {}: '{}' needs an admin client", peer_, r.cmd);
      Send(ReplyError(r.id, errc::kForbidden,
                      r.cmd + " needs an admin client: authenticate with the admin token"));
      return;
    }
    StateMachine& state = server_->state;
    if (r.cmd == "auth") {
      authed_ = true;  // no token configured: nothing to check
      Send(ReplyOk(r.id, {{"role", "admin"}}));
    } else if (r.cmd == "ping") {
      Send(ReplyOk(r.id, {{"pong", true}}));
    } else if (r.cmd == "status") {
      nlohmann::json fields = server_->jobs->Snapshot();
      fields["state"] = StateName(state.state());
      fields["reason"] = state.last_reason();
      fields["clients"] = server_->clients.load();
      Send(ReplyOk(r.id, std::move(fields)));
    } else if (r.cmd == "arm" || r.cmd == "disarm") {
      const Status st = r.cmd == "arm" ? state.Arm() : state.Disarm();
      Send(st.ok() ? ReplyOk(r.id, {{"state", StateName(state.state())}}) : ReplyError(r.id, st));
    } else if (r.cmd == "subscribe") {
      subscribed_ = true;
      Send(ReplyOk(r.id, {{"state", StateName(state.state())}}));
    } else if (r.cmd == "run") {
      Send(server_->Run(r));
    } else if (r.cmd == "cancel") {
      Send(server_->Cancel(r));
    } else if (r.cmd == "ack") {
      // The prompt by its id: an answer meant for one step never confirms the next.
      const double id = r.body["prompt_id"].get<double>();
      if (!(id >= 1 && id <= 1e9 && id == std::floor(id))) {
        Send(ReplyError(r.id, errc::kBadArgument, "ack: \"prompt_id\" must be a prompt's number"));
        return;
      }
      const bool abort = r.body.contains("abort") && r.body["abort"].get<bool>();
      const Status st = server_->jobs->Ack(static_cast<int>(id), !abort);
      Send(st.ok() ? ReplyOk(r.id, {{"prompt_id", static_cast<int>(id)}}) : ReplyError(r.id, st));
    } else if (r.cmd == "result") {
      Send(server_->ResultOf(r));
    } else if (r.cmd == "list_results") {
      Send(server_->ListResults(r));
    } else if (r.cmd == "shutdown") {
      server_->log->info("shutdown asked by {}", peer_);
      Send(ReplyOk(r.id));
      server_->RequestShutdown();
    } else {
      Send(ReplyError(r.id, errc::kInternal, r.cmd + ": in the command table but without a handler"));
    }
  }

  Impl* server_;
  asio::ip::tcp::socket socket_;
  asio::streambuf buffer_;
  asio::steady_timer timer_;       // idle
  asio::steady_timer auth_timer_;  // the auth deadline, while in the unauthenticated pool
  std::deque<std::string> out_;
  std::string address_;  // the peer's IP, the per-address limit's key
  std::string peer_;
  Slot slot_ = Slot::kNone;
  bool address_counted_ = false;
  bool authed_ = false, admin_ = false, subscribed_ = false, closing_ = false, closed_ = false;
};

void Server::Impl::Accept() {
  acceptor.async_accept([this](const asio::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec) {
      if (ec == asio::error::operation_aborted || !acceptor.is_open()) return;
      // Out of file descriptors and the like: try again shortly, not in a tight loop.
      log->warn("accept: {}; retrying in 100 ms", ec.message());
      accept_retry.expires_after(std::chrono::milliseconds(100));
      accept_retry.async_wait([this](const asio::error_code& e) {
        if (!e && acceptor.is_open()) Accept();
      });
      return;
    }
    auto session = std::make_shared<Session>(this, std::move(socket));
    sessions.insert(session);
    ++clients;
    const std::string refused = session->Admit();
    if (!refused.empty()) {
      // Debug only: a flood would otherwise write a line per connection.
      log->debug("refused {}: {}", session->peer(), refused);
      session->SendAndClose(ReplyError(nullptr, errc::kTooManyClients, refused));
    } else {
      session->Begin();
    }
    Accept();
  });
}

void Server::Impl::Broadcast(const std::string& line) {
  for (const auto& s : std::vector<std::shared_ptr<Session>>(sessions.begin(), sessions.end())) {
    if (s->subscribed()) s->Send(line);
  }
}

namespace {

nlohmann::json RecordJson(const JobRecord& r) {
  return {{"job_id", r.id},     {"job", r.job},         {"status", r.status},
          {"reason", r.reason}, {"started", r.started}, {"finished", r.finished}};
}

}  // namespace

std::string Server::Impl::Run(const Request& r) {
  std::vector<std::string> sets;
  if (r.body.contains("set")) {
    for (auto it = r.body["set"].begin(); it != r.body["set"].end(); ++it) {
      const nlohmann::json& v = it.value();
      sets.push_back(it.key() + "=" + (v.is_string() ? v.get<std::string>() : v.dump()));
    }
  }
  // A client changes a job's settings, never the files it reads or writes (confine.h).
  const Status keys = CheckSetKeys(sets);
  if (!keys.ok()) return ReplyError(r.id, keys);
  if (!options.machine_sets.empty()) {
    for (const std::string& s : sets) {
      if (s.rfind("machine.", 0) == 0 || s.rfind("machine=", 0) == 0) {
        return ReplyError(r.id, InvalidArgument("set: '" + s.substr(0, s.find('=')) +
                                                "': this daemon's cell is its configuration's "
                                                "machine: section; a job cannot change it"));
      }
    }
  }
  // The daemon's machine wins over the job's and the client's: it owns the cell.
  sets.insert(sets.end(), options.machine_sets.begin(), options.machine_sets.end());
  const nlohmann::json& spec = r.body["job"];
  // Files a job reads: inside the read roots, or the cell's own.
  ReadRoots roots;
  roots.folders = options.read_roots.empty() ? std::vector<std::string>{options.jobs_dir}
                                             : options.read_roots;
  for (const std::string& s : options.machine_sets) {
    const size_t eq = s.find('=');
    if (eq != std::string::npos && NamesAFile(s.substr(0, eq))) roots.files.push_back(s.substr(eq + 1));
  }
  const auto load = [&]() -> Result<job::LoadedJob> {
    if (!spec.is_string()) {
      INSITU_RETURN_IF_ERROR(CheckInlineJob(spec, options.jobs_dir));
      return job::LoadJobText(spec.dump(), "<run request>", options.jobs_dir, sets);
    }
    // A job file inside the jobs folder only, and what it names (its world first: loading
    // reads it) inside the read roots.
    INSITU_ASSIGN_OR_RETURN(const std::string path,
                            JobPathInside(options.jobs_dir, spec.get<std::string>()));
    const auto raw = ConfigNode::LoadFile(path);
    if (raw.ok()) {
      INSITU_RETURN_IF_ERROR(CheckReads(*raw, std::filesystem::path(path).parent_path().string(),
                                        roots, !options.machine_sets.empty()));
    }
    return job::LoadJobFile(path, sets);
  };
  Result<job::LoadedJob> loaded = load();
  if (!loaded.ok()) return ReplyError(r.id, loaded.status());
  // The job as it will run (the cell's files in it): every file inside the roots, and a world
  // file's base beside it.
  Status reads = CheckReads(loaded->root, loaded->folder, roots);
  const ConfigNode world_file = loaded->root.Child("world");
  const ConfigNode base = loaded->world.Child("base");
  if (reads.ok() && world_file.IsScalar() && base.IsScalar()) {
    const std::string world_path = job::ResolvePath(loaded->folder, *world_file.AsString());
    const std::string base_path = job::ResolvePath(
        std::filesystem::path(world_path).parent_path().string(), *base.AsString());
    if (!InsideRoots(base_path, roots)) {
      reads = InvalidArgument(base.Where() + ": '" + *base.AsString() +
                              "' is outside the folders this daemon reads (read_roots)");
    }
  }
  if (!reads.ok()) return ReplyError(r.id, reads);
  // Refused here, by file, line and key, before the machine is touched.
  const Status checked = job::CheckJob(*loaded);
  if (!checked.ok()) return ReplyError(r.id, checked);
  auto submitted = jobs->Submit(std::move(*loaded));
  if (!submitted.ok()) return ReplyError(r.id, submitted.status());
  nlohmann::json fields = {{"job_id", submitted->id}, {"job", submitted->kind}};
  if (submitted->position > 0) {
    fields["queued"] = true;
    fields["position"] = submitted->position;
  }
  return ReplyOk(r.id, std::move(fields));
}

std::string Server::Impl::Cancel(const Request& r) {
  const std::string id = r.body.contains("job_id") ? r.body["job_id"].get<std::string>() : "";
  auto cancelled = jobs->Cancel(id);
  if (!cancelled.ok()) return ReplyError(r.id, cancelled.status());
  return ReplyOk(r.id, {{"job_id", *cancelled}});
}

std::string Server::Impl::ResultOf(const Request& r) {
  auto record = store->Get(r.body["job_id"].get<std::string>());
  if (!record.ok()) return ReplyError(r.id, record.status());
  nlohmann::json report;  // null until the job has written one
  std::ifstream f(std::filesystem::path(record->dir) / "report.json");
  if (f) {
    std::stringstream ss;
    ss << f.rdbuf();
    report = nlohmann::json::parse(ss.str(), nullptr, false);
    if (report.is_discarded()) report = nullptr;
  }
  return ReplyOk(r.id, {{"result", RecordJson(*record)}, {"report", report}});
}

std::string Server::Impl::ListResults(const Request& r) {
  nlohmann::json list = nlohmann::json::array();
  for (const JobRecord& rec : store->List()) list.push_back(RecordJson(rec));
  return ReplyOk(r.id, {{"results", list}});
}

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {
  impl_->state.AddListener([impl = impl_.get()](MachineState from, MachineState to,
                                                const std::string& reason) {
    const std::string line =
        EventLine("state", {{"from", StateName(from)}, {"to", StateName(to)}, {"reason", reason}});
    asio::post(impl->io, [impl, line] { impl->Broadcast(line); });
  });
}

Server::~Server() { Stop(); }

Status Server::Start() {
  INSITU_RETURN_IF_ERROR(impl_->options.Validate());
  {
    auto store = ResultsStore::Open(impl_->options.results_dir);
    if (!store.ok()) return store.status();
    if (store->interrupted_at_open() > 0) {
      impl_->log->warn("{} job(s) were running when the daemon last stopped: marked interrupted",
                       store->interrupted_at_open());
    }
    impl_->store = std::make_unique<ResultsStore>(std::move(*store));
  }
  QueueOptions queue{impl_->options.queue, impl_->options.max_queued};
  impl_->jobs = std::make_unique<JobQueue>(
      &impl_->state, impl_->store.get(), queue,
      [impl = impl_.get()](const std::string& event, nlohmann::json fields) {
        // Posted: a request's reply is sent before the events it causes.
        const std::string line = EventLine(event, std::move(fields));
        asio::post(impl->io, [impl, line] { impl->Broadcast(line); });
      });
  asio::error_code ec;
  const asio::ip::tcp::endpoint ep(asio::ip::make_address(impl_->options.bind_address),
                                   static_cast<unsigned short>(impl_->options.port));
  impl_->acceptor.open(ep.protocol(), ec);
  if (!ec) impl_->acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) impl_->acceptor.bind(ep, ec);
  if (!ec) impl_->acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    return Status(StatusCode::kDeviceError, "cannot listen on " + impl_->options.bind_address +
                                                ":" + std::to_string(impl_->options.port) + ": " +
                                                ec.message());
  }
  impl_->bound_port = impl_->acceptor.local_endpoint().port();
  impl_->Accept();
  impl_->running = true;
  impl_->thread = std::thread([impl = impl_.get()] {
    // Handlers catch nothing on purpose: a handler that threw would be a bug. Logged, and the
    // loop goes on so one bad connection cannot take the daemon down.
    for (;;) {
      try {
        impl->io.run();
        return;
      } catch (const std::exception& e) {
        impl->log->error("handler failed: {}", e.what());
      }
    }
  });
  impl_->log->info("listening on {}:{}", impl_->options.bind_address, impl_->bound_port);
  return Status::Ok();
}

int Server::port() const { return impl_->bound_port; }

void Server::Stop() {
  if (!impl_->running.exchange(false)) return;  // the signal thread and main may both stop
  if (impl_->jobs) impl_->jobs->Stop();  // a running job stops at its next check, state saved
  asio::post(impl_->io, [impl = impl_.get()] {
    asio::error_code ec;
    impl->acceptor.close(ec);
    impl->accept_retry.cancel();
    for (const auto& s : std::vector<std::shared_ptr<Impl::Session>>(impl->sessions.begin(),
                                                                     impl->sessions.end())) {
      s->Close();
    }
    impl->io.stop();
  });
  if (impl_->thread.joinable()) impl_->thread.join();
  impl_->RequestShutdown();
}

void Server::WaitForShutdown() {
  std::unique_lock<std::mutex> lock(impl_->shutdown_mutex);
  impl_->shutdown_cv.wait(lock, [this] { return impl_->shutdown; });
}

StateMachine& Server::state() { return impl_->state; }

int Server::connected_clients() const { return impl_->clients.load(); }

}  // namespace insitu::daemon
