// The command socket on a loopback port with real TCP clients: the commands served, every
// hostile input answered (or its connection closed) with the daemon still answering ping,
// authentication, state events to subscribers, and 100 clients at once.
#include "insitu/daemon/server.h"

#define ASIO_STANDALONE
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/time.h>

#include <asio.hpp>
#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace insitu::daemon {
namespace {

// A blocking client with a 5 s receive timeout (a hung daemon fails the test, never hangs it).
class Client {
 public:
  explicit Client(int port) : socket_(io_) {
    socket_.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)});
    timeval tv{5, 0};
    setsockopt(socket_.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  void SendRaw(const std::string& bytes) { asio::write(socket_, asio::buffer(bytes)); }
  // The next line, without its newline; "" when the connection closed (or timed out).
  std::string ReadLine() {
    asio::error_code ec;
    const size_t n = asio::read_until(socket_, buffer_, '\n', ec);
    if (ec) return "";
    std::string line(asio::buffers_begin(buffer_.data()),
                     asio::buffers_begin(buffer_.data()) + n - 1);
    buffer_.consume(n);
    return line;
  }
  nlohmann::json Call(const std::string& line) {
    SendRaw(line + "\n");
    const std::string reply = ReadLine();
    return reply.empty() ? nlohmann::json() : nlohmann::json::parse(reply, nullptr, false);
  }
  bool Closed() { return ReadLine().empty(); }

 private:
  asio::io_context io_;
  asio::ip::tcp::socket socket_;
  asio::streambuf buffer_;
};

ServerOptions Loopback() {
  ServerOptions o;
  o.port = 0;
  o.max_line_bytes = 4096;
  return o;
}

bool Pong(Client& c) {
  const auto r = c.Call(R"({"id": "p", "cmd": "ping"})");
  return r.is_object() && r["ok"] == true && r["pong"] == true && r["id"] == "p";
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
  // Not served yet: a clear error, not a silence.
  EXPECT_EQ(operator_.Call(R"({"id": 5, "cmd": "cancel"})")["error"]["code"], "not_implemented");
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

TEST(Server, BadOptionsAndABusyPortAreNamed) {
  ServerOptions bad = Loopback();
  bad.bind_address = "not-an-address";
  EXPECT_EQ(Server(bad).Start().code(), StatusCode::kInvalidArgument);
  Server first(Loopback());
  ASSERT_TRUE(first.Start().ok());
  ServerOptions same = Loopback();
  same.port = first.port();
  const Status busy = Server(same).Start();
  EXPECT_EQ(busy.code(), StatusCode::kDeviceError);
  EXPECT_NE(busy.message().find(std::to_string(first.port())), std::string::npos);
}

}  // namespace
}  // namespace insitu::daemon
