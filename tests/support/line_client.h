// A blocking JSON-lines client for the command socket, as an integrator's script would be:
// calls, events kept in order, and reads that give up after 10 s (a hung daemon fails the
// test, never hangs it).
#pragma once

#define ASIO_STANDALONE
#include <poll.h>

#include <algorithm>
#include <asio.hpp>
#include <deque>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace insitu::testing {

// A blocking client whose reads give up after 10 s (a hung daemon fails the test, never hangs it).
class Client {
 public:
  explicit Client(int port) : socket_(io_) {
    socket_.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)});
  }
  void SendRaw(const std::string& bytes) { asio::write(socket_, asio::buffer(bytes)); }
  // The next line, without its newline; "" when the connection closed (or nothing came within
  // timeout_ms). Events that arrived while a call waited for its reply come first.
  std::string ReadLine(int timeout_ms = 10000) {
    if (!pending_.empty()) {
      std::string line = pending_.front();
      pending_.pop_front();
      return line;
    }
    return NextLine(timeout_ms);
  }
  // Sends a request and returns its reply; events that come first are kept for ReadLine.
  nlohmann::json Call(const std::string& line) {
    SendRaw(line + "\n");
    for (;;) {
      const std::string reply = NextLine();
      if (reply.empty()) return nlohmann::json();
      const auto j = nlohmann::json::parse(reply, nullptr, false);
      if (j.is_object() && j.contains("event")) {
        pending_.push_back(reply);
        continue;
      }
      return j;
    }
  }
  bool Closed() { return ReadLine().empty(); }

 private:
  // One line from the socket, waiting at most timeout_ms for it (poll: asio's blocking reads
  // ignore SO_RCVTIMEO); "" on close or timeout.
  std::string NextLine(int timeout_ms = 10000) {
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

  asio::io_context io_;
  asio::ip::tcp::socket socket_;
  asio::streambuf buffer_;
  std::deque<std::string> pending_;
};

inline bool Pong(Client& c) {
  const auto r = c.Call(R"({"id": "p", "cmd": "ping"})");
  return r.is_object() && r["ok"] == true && r["pong"] == true && r["id"] == "p";
}

// Reads lines until a job event with a final status (done, faulted, cancelled), of job `id`
// when given; every line read is kept in *events when given. Null if the connection closed
// or went silent for 120 s: a job's phase may send no progress for many seconds when the
// machine is busy (a profiler job beside an integration test under ctest -j2 was silent for
// over 10 s), and a hung daemon still fails the test well within ctest's timeout.
inline nlohmann::json WaitForJobEnd(Client& c, const std::string& id = "",
                                    std::vector<nlohmann::json>* events = nullptr) {
  for (int k = 0; k < 100000; ++k) {
    const std::string line = c.ReadLine(120000);
    if (line.empty()) return nullptr;
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (events != nullptr && j.is_object()) events->push_back(j);
    if (j.is_object() && j.value("event", "") == "job" && j.value("status", "") != "running" &&
        j.value("status", "") != "queued" && (id.empty() || j.value("job_id", "") == id)) {
      return j;
    }
  }
  return nullptr;
}

}  // namespace insitu::testing
