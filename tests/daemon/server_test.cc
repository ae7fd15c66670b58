// The command socket on a loopback port with real TCP clients: the commands served, every
// hostile input answered (or its connection closed) with the daemon still answering ping,
// authentication, state events to subscribers, 100 clients at once, and a flood of connections
// without the token that locks no operator out.
#include "insitu/daemon/server.h"

#include "support/line_client.h"

#define ASIO_STANDALONE
#include <gtest/gtest.h>
#include <poll.h>

#include <algorithm>
#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <deque>
#include <filesystem>
#include <memory>
#include <fstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace insitu::daemon {
namespace {

using testing::Client;
using testing::Pong;
using testing::WaitForJobEnd;

ServerOptions Loopback(const char* results = "insitu_server_test_results") {
  ServerOptions o;
  o.port = 0;
  o.max_line_bytes = 4096;
  o.results_dir = (std::filesystem::temp_directory_path() / results).string();
  o.jobs_dir = INSITU_SOURCE_DIR;
  return o;
}

TEST(Server, ServesTheStateCommandsAndEvents) {
  Server server(Loopback());
  ASSERT_TRUE(server.Start().ok());
  Client watcher(server.port()), operator_(server.port());
  EXPECT_TRUE(Pong(operator_));
  EXPECT_EQ(watcher.Call(R"({"id": 1, "cmd": "subscribe"})")["state"], "idle");
  EXPECT_EQ(operator_.Call(R"({"id": 2, "cmd": "arm"})")["state"], "armed");
  const auto event = nlohmann::json::parse(watcher.ReadLine());
  EXPECT_EQ(event["event"], "state");
  EXPECT_EQ(event["from"], "idle");
  EXPECT_EQ(event["to"], "armed");
  EXPECT_EQ(operator_.Call(R"({"id": 3, "cmd": "status"})")["state"], "armed");
  EXPECT_EQ(operator_.Call(R"({"id": 4, "cmd": "disarm"})")["state"], "idle");
  EXPECT_EQ(nlohmann::json::parse(watcher.ReadLine())["to"], "idle");
  // Nothing to cancel: a clear error, not a silence.
  EXPECT_EQ(operator_.Call(R"({"id": 5, "cmd": "cancel"})")["error"]["code"], "wrong_state");
}

TEST(Server, HostileInputIsAnsweredAndTheDaemonStaysUp) {
  Server server(Loopback());
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  const auto code = [&](const std::string& line) {
    return c.Call(line)["error"]["code"].get<std::string>();
  };
  EXPECT_EQ(code("this is not json"), "invalid_json");
  EXPECT_EQ(code(std::string("\x00\x01\xfe\xff garbage", 12)), "invalid_json");
  EXPECT_EQ(code(R"({"id": 1, "cmd": 42})"), "bad_type");
  EXPECT_EQ(code(R"({"id": 1, "cmd": "teleport"})"), "unknown_command");
  EXPECT_EQ(code(R"({"id": 1, "cmd": "ping", "loud": true})"), "bad_argument");
  EXPECT_EQ(code(R"({"id": 1, "cmd": "run", "job": 7})"), "bad_argument");
  EXPECT_EQ(code("[1, 2, 3]"), "not_an_object");
  EXPECT_TRUE(Pong(c));  // the same connection goes on

  // A line over the limit closes that connection only.
  Client flood(server.port());
  flood.SendRaw(std::string(10000, 'x'));
  EXPECT_EQ(nlohmann::json::parse(flood.ReadLine())["error"]["code"], "line_too_long");
  EXPECT_TRUE(flood.Closed());
  EXPECT_TRUE(Pong(c));

  // Half a line, then silence: the others are served meanwhile.
  Client staller(server.port());
  staller.SendRaw(R"({"id": 1, "cmd": "pi)");
  EXPECT_TRUE(Pong(c));
  // A client that disconnects in the middle of a line.
  {
    Client quitter(server.port());
    quitter.SendRaw(R"({"id": 9, "cmd": "sta)");
  }
  EXPECT_TRUE(Pong(c));
}

// A client names a job inside the jobs folder and changes its settings; it cannot reach a file
// outside the folder, redirect what the job writes, or read a file back through an error.
TEST(Server, AClientStaysInsideTheDaemonsFolders) {
  namespace fs = std::filesystem;
  const fs::path secret = fs::temp_directory_path() / "insitu_server_test_secret.yaml";
  std::ofstream(secret) << "job: scan\nsecret_line: hunter2\n";
  Server server(Loopback());
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  const auto refused = [&](const std::string& job, const std::string& set) {
    const auto reply = c.Call(R"({"id": 1, "cmd": "run", "job": )" + job +
                              (set.empty() ? "" : R"(, "set": )" + set) + "}");
    EXPECT_EQ(reply["ok"], false) << reply.dump();
    const std::string text = reply.dump();
    EXPECT_EQ(text.find("hunter2"), std::string::npos) << text;  // never a file's contents
    return reply["error"]["message"].get<std::string>();
  };
  EXPECT_NE(refused("\"" + secret.string() + "\"", "").find("absolute path"), std::string::npos);
  EXPECT_NE(refused(R"("config/../../../../tmp/insitu_server_test_secret.yaml")", "").find(".."),
            std::string::npos);
  const fs::path planted = fs::temp_directory_path() / "insitu_server_test_planted.yaml";
  fs::remove(planted);
  EXPECT_NE(refused(R"("config/jobs/calibrate.yaml")",
                    R"({"output.calibration": ")" + planted.string() + R"("})")
                .find("names a file"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(planted));
  EXPECT_TRUE(Pong(c));
}

TEST(Server, AWrongTokenClosesTheConnection) {
  ServerOptions o = Loopback();
  o.token = "s3cret-token";
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  Client early(server.port());
  EXPECT_EQ(early.Call(R"({"id": 1, "cmd": "ping"})")["error"]["code"], "unauthorized");
  EXPECT_TRUE(early.Closed());
  Client wrong(server.port());
  EXPECT_EQ(wrong.Call(R"({"id": 1, "cmd": "auth", "token": "guess"})")["error"]["code"],
            "unauthorized");
  EXPECT_TRUE(wrong.Closed());
  Client right(server.port());
  EXPECT_EQ(right.Call(R"({"id": 1, "cmd": "auth", "token": "s3cret-token"})")["ok"], true);
  EXPECT_TRUE(Pong(right));
}

TEST(Server, AHundredClientsAtOnce) {
  Server server(Loopback());
  ASSERT_TRUE(server.Start().ok());
  std::vector<std::thread> threads;
  std::atomic<int> answered{0};
  for (int t = 0; t < 100; ++t) {
    threads.emplace_back([&] {
      Client c(server.port());
      for (int k = 0; k < 10; ++k) answered += Pong(c);
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(answered.load(), 1000);
}

// A connection from a chosen source address: all of 127.0.0.0/8 is this host, so loopback
// plays several peers. Blocking, reads give up after a timeout (a hung daemon fails the test).
class Peer {
 public:
  Peer(asio::io_context& io, const char* from, int port) : socket_(io) {
    socket_.open(asio::ip::tcp::v4());
    socket_.bind({asio::ip::make_address(from), 0});
    socket_.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)});
  }
  // The next line; "" on close or after timeout_ms.
  std::string ReadLine(int timeout_ms = 10000) {
    for (;;) {
      const auto begin = asio::buffers_begin(buffer_.data());
      const auto end = asio::buffers_end(buffer_.data());
      const auto nl = std::find(begin, end, '\n');
      if (nl != end) {
        std::string line(begin, nl);
        buffer_.consume(line.size() + 1);
        return line;
      }
      pollfd p{socket_.native_handle(), POLLIN, 0};
      if (poll(&p, 1, timeout_ms) <= 0) return "";
      asio::error_code ec;
      const size_t n = socket_.read_some(buffer_.prepare(4096), ec);
      if (ec || n == 0) return "";
      buffer_.commit(n);
    }
  }
  nlohmann::json Call(const std::string& line) {
    asio::error_code ec;
    asio::write(socket_, asio::buffer(line + "\n"), ec);
    return nlohmann::json::parse(ReadLine(), nullptr, false);
  }
  // The error code of the line the daemon sent before closing; "" if it sent none or kept the
  // connection open.
  std::string ClosedWith(int timeout_ms = 10000) {
    const auto line = nlohmann::json::parse(ReadLine(timeout_ms), nullptr, false);
    if (!line.is_object() || !ReadLine(timeout_ms).empty()) return "";
    return line["error"].value("code", "");
  }

 private:
  asio::ip::tcp::socket socket_;
  asio::streambuf buffer_;
};

// The tester's attack: with a token set, one peer opens 300 connections and never sends a byte.
TEST(Server, AFloodWithoutTheTokenLocksNoOperatorOut) {
  ServerOptions o = Loopback();
  o.token = "s3cret-token";
  o.auth_timeout_s = 2.0;  // 5 s by default; the same code, a shorter test
  ASSERT_EQ(o.max_unauthenticated, 16);
  ASSERT_EQ(o.max_clients_per_address, 32);
  ASSERT_EQ(o.max_clients, 256);
  Server server(o);
  ASSERT_TRUE(server.Start().ok());
  const int port = server.port();
  const std::string auth = R"({"id": 1, "cmd": "auth", "token": "s3cret-token"})";
  const std::string ping = R"({"id": "p", "cmd": "ping"})";
  using Clock = std::chrono::steady_clock;
  const auto seconds_since = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  asio::io_context io;

  // An operator has connected and not yet authenticated when the flood comes.
  Peer early(io, "127.0.0.1", port);
  const auto flood_start = Clock::now();
  std::vector<std::unique_ptr<Peer>> flood;
  for (int k = 0; k < 300; ++k) flood.push_back(std::make_unique<Peer>(io, "127.0.0.2", port));
  // One address may wait on a quarter of the pool (4 of 16); the other 296 are refused at once
  // (their line written, then closed), long before the auth deadline.
  // (The count rises as the daemon accepts them: wait for it to reach its cap, not below it.)
  while (server.connected_clients() != 5 && seconds_since(flood_start) < 10) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(server.connected_clients(), 5);
  ASSERT_LT(seconds_since(flood_start), o.auth_timeout_s);

  // While the flood goes on: the operator's auth takes it out of the pool into one of the 256
  // slots, which no connection without the token can hold, and its ping is answered...
  EXPECT_EQ(early.Call(auth)["role"], "operator");
  EXPECT_EQ(early.Call(ping)["pong"], true);
  // ... and operators who connect now find the pool open: the flooder cannot fill it.
  Peer late(io, "127.0.0.1", port);
  EXPECT_EQ(late.Call(auth)["role"], "operator");
  EXPECT_EQ(late.Call(ping)["pong"], true);
  Peer more_flood(io, "127.0.0.2", port);
  EXPECT_EQ(more_flood.ClosedWith(), "too_many_clients");
  EXPECT_LT(seconds_since(flood_start), o.auth_timeout_s);  // all this with the flood held

  // The auth deadline closes the 4 held, each with its error line; nothing holds on.
  int refused = 0, timed_out = 0;
  for (auto& f : flood) {
    const std::string code = f->ClosedWith();
    refused += code == "too_many_clients";
    timed_out += code == "auth_timeout";
  }
  EXPECT_EQ(refused, 296);
  EXPECT_EQ(timed_out, 4);
  // The deadline counts from the accept, plus the loop's 10 ms steps: well within 1 s more.
  EXPECT_LT(seconds_since(flood_start), o.auth_timeout_s + 1.0);
  EXPECT_EQ(early.Call(ping)["pong"], true);  // authenticated: no deadline
  EXPECT_EQ(late.Call(ping)["pong"], true);
  Peer after(io, "127.0.0.2", port);  // the pool is free again, for the flooder too
  EXPECT_EQ(after.Call(auth)["role"], "operator");

  // One address holds 32 connections at most, authenticated ones included.
  std::vector<std::unique_ptr<Peer>> many;
  for (int k = 0; k < 32; ++k) {
    many.push_back(std::make_unique<Peer>(io, "127.0.0.3", port));
    ASSERT_EQ(many.back()->Call(auth)["role"], "operator") << k;
  }
  Peer one_more(io, "127.0.0.3", port);
  EXPECT_EQ(one_more.ClosedWith(), "too_many_clients");
  Peer elsewhere(io, "127.0.0.4", port);
  EXPECT_EQ(elsewhere.Call(auth)["role"], "operator");
  EXPECT_EQ(elsewhere.Call(ping)["pong"], true);
}

TEST(Server, BadOptionsAndABusyPortAreNamed) {
  ServerOptions bad = Loopback();
  bad.bind_address = "not-an-address";
  EXPECT_EQ(Server(bad).Start().code(), StatusCode::kInvalidArgument);
  for (const auto& [set, key] : std::vector<std::pair<void (*)(ServerOptions*), std::string>>{
           {[](ServerOptions* o) { o->auth_timeout_s = 0; }, "auth_timeout_s"},
           {[](ServerOptions* o) { o->max_unauthenticated = 0; }, "max_unauthenticated"},
           {[](ServerOptions* o) { o->max_clients_per_address = 0; }, "max_clients_per_address"},
       }) {
    ServerOptions o = Loopback();
    set(&o);
    const Status st = o.Validate();
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << key;
    EXPECT_EQ(st.message().rfind(key, 0), 0u) << st.message();
  }
  Server first(Loopback());
  ASSERT_TRUE(first.Start().ok());
  ServerOptions same = Loopback();
  same.port = first.port();
  const Status busy = Server(same).Start();
  EXPECT_EQ(busy.code(), StatusCode::kDeviceError);
  EXPECT_NE(busy.message().find(std::to_string(first.port())), std::string::npos);
}

TEST(Server, RunsAScanJobAndKeepsItsResultAcrossARestart) {
  std::filesystem::remove_all(std::filesystem::temp_directory_path() / "insitu_server_jobs");
  std::string job_id;
  {
    Server server(Loopback("insitu_server_jobs"));
    ASSERT_TRUE(server.Start().ok());
    Client c(server.port());
    // The shipped scan job, cut to 3 lines so it takes a second.
    const std::string run = R"({"id": 1, "cmd": "run", "job": "config/jobs/scan_step_gauge.yaml",)"
                            R"( "set": {"scan.x_start_mm": -3.0, "scan.x_end_mm": -2.0}})";
    EXPECT_EQ(c.Call(run)["error"]["code"], "wrong_state");  // not armed
    ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "subscribe"})")["ok"], true);
    ASSERT_EQ(c.Call(R"({"id": 3, "cmd": "arm"})")["ok"], true);
    const auto started = c.Call(run);
    ASSERT_EQ(started["ok"], true) << started.dump();
    job_id = started["job_id"];
    const auto done = WaitForJobEnd(c);
    ASSERT_TRUE(done.is_object());
    ASSERT_EQ(done["status"], "done") << done.dump();
    EXPECT_EQ(done["job_id"], job_id);
    const auto result = c.Call(R"({"id": 4, "cmd": "result", "job_id": ")" + job_id + R"("})");
    EXPECT_EQ(result["result"]["status"], "done");
    EXPECT_EQ(result["report"]["job"], "scan");
    EXPECT_EQ(result["report"]["ok"], true);
    EXPECT_GT(result["report"]["metrics"]["points"].get<double>(), 100.0);
    EXPECT_EQ(c.Call(R"({"id": 5, "cmd": "status"})")["state"], "done");
    // A bad job is refused before anything moves, by name.
    ASSERT_EQ(c.Call(R"({"id": 6, "cmd": "arm"})")["ok"], true);
    const auto reply = c.Call(R"({"id": 7, "cmd": "run", "job": {"job": "teleport"}})");
    EXPECT_EQ(reply["ok"], false);
    EXPECT_NE(reply["error"]["message"].get<std::string>().find("teleport"), std::string::npos);
  }
  Server again(Loopback("insitu_server_jobs"));
  ASSERT_TRUE(again.Start().ok());
  Client c(again.port());
  const auto list = c.Call(R"({"id": 1, "cmd": "list_results"})");
  ASSERT_EQ(list["results"].size(), 1u);
  EXPECT_EQ(list["results"][0]["job_id"], job_id);
  EXPECT_EQ(list["results"][0]["status"], "done");
}

// Each injected device fault ends its job Faulted with the reason, the machine out of Running
// (the laser not allowed), the daemon answering, and the next job runs.
TEST(Server, InjectedFaultsFaultTheJobNotTheDaemon) {
  Server server(Loopback("insitu_server_faults"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  const std::string job =
      R"("job": "config/jobs/scan_step_gauge.yaml", "set": {"scan.x_start_mm": -3.0, )"
      R"("scan.x_end_mm": -2.0)";
  const std::vector<std::pair<std::string, std::string>> faults{
      {R"("world.faults.camera_timeout_at_frame": 1)", "camera timeout"},
      {R"("world.faults.scanner_error_at_command": 1)", "scan head error"},
      {R"("world.faults.camera_drop_frame_at": 1)", "packets lost"},
      // A truncated payload is caught before any image code reads past its end.
      {R"("world.faults.camera_corrupt_frame_at": 2)", "corrupt"},
  };
  for (const auto& [fault, words] : faults) {
    ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
    const auto started = c.Call(R"({"id": 3, "cmd": "run", )" + job + ", " + fault + "}}");
    ASSERT_EQ(started["ok"], true) << started.dump();
    const auto end = WaitForJobEnd(c);
    ASSERT_TRUE(end.is_object());
    EXPECT_EQ(end["status"], "faulted") << end.dump();
    EXPECT_NE(end["reason"].get<std::string>().find(words), std::string::npos) << end.dump();
    EXPECT_EQ(c.Call(R"({"id": 4, "cmd": "status"})")["state"], "faulted");
    EXPECT_FALSE(server.state().laser_allowed());
    EXPECT_TRUE(Pong(c));
  }
  // The next job runs.
  ASSERT_EQ(c.Call(R"({"id": 5, "cmd": "arm"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 6, "cmd": "run", )" + job + "}}")["ok"], true);
  const auto end = WaitForJobEnd(c);
  ASSERT_TRUE(end.is_object());
  EXPECT_EQ(end["status"], "done") << end.dump();
}

TEST(Server, CancelStopsTheRunningJob) {
  Server server(Loopback("insitu_server_cancel"));
  ASSERT_TRUE(server.Start().ok());
  Client c(server.port());
  ASSERT_EQ(c.Call(R"({"id": 1, "cmd": "subscribe"})")["ok"], true);
  ASSERT_EQ(c.Call(R"({"id": 2, "cmd": "arm"})")["ok"], true);
  // The whole step-gauge scan: 57 lines, several seconds.
  const auto started =
      c.Call(R"({"id": 3, "cmd": "run", "job": "config/jobs/scan_step_gauge.yaml"})");
  ASSERT_EQ(started["ok"], true) << started.dump();
  // One job at a time.
  EXPECT_EQ(
      c.Call(
          R"({"id": 4, "cmd": "run", "job": "config/jobs/scan_step_gauge.yaml"})")["error"]["code"],
      "wrong_state");
  EXPECT_EQ(c.Call(R"({"id": 5, "cmd": "disarm"})")["error"]["code"], "wrong_state");
  EXPECT_EQ(c.Call(R"({"id": 6, "cmd": "cancel"})")["ok"], true);
  const auto end = WaitForJobEnd(c);
  ASSERT_TRUE(end.is_object());
  EXPECT_EQ(end["status"], "cancelled") << end.dump();
  EXPECT_EQ(c.Call(R"({"id": 7, "cmd": "status"})")["state"], "cancelled");
  const auto result = c.Call(R"({"id": 8, "cmd": "result", "job_id": ")" +
                             started["job_id"].get<std::string>() + "\"}");
  EXPECT_EQ(result["result"]["status"], "cancelled");
  EXPECT_TRUE(server.state().Disarm().ok());
  EXPECT_FALSE(server.state().laser_allowed());
}

}  // namespace
}  // namespace insitu::daemon
