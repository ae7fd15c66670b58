// The command socket under load: 100 clients, each sending 100 pings one after another, all at
// once against an in-process server on a loopback port. Reports every ping answered, the
// latency percentiles, and (the baseline measured in the same run) one client alone.
#define ASIO_STANDALONE
#include <benchmark/benchmark.h>

#include <algorithm>
#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "insitu/daemon/server.h"

namespace {

using Clock = std::chrono::steady_clock;

// Each client's ping latencies (us); returns the number answered.
int PingLoop(int port, int pings, std::vector<double>* latencies_us) {
  asio::io_context io;
  asio::ip::tcp::socket s(io);
  s.connect({asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)});
  s.set_option(asio::ip::tcp::no_delay(true));
  asio::streambuf buf;
  int answered = 0;
  const std::string ping = "{\"id\": 1, \"cmd\": \"ping\"}\n";
  for (int k = 0; k < pings; ++k) {
    const auto t0 = Clock::now();
    asio::write(s, asio::buffer(ping));
    asio::error_code ec;
    const size_t n = asio::read_until(s, buf, '\n', ec);
    if (ec) break;
    const std::string line(asio::buffers_begin(buf.data()), asio::buffers_begin(buf.data()) + n);
    buf.consume(n);
    answered += line.find("\"pong\":true") != std::string::npos;
    latencies_us->push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  return answered;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * (v.size() - 1))];
}

void Run(benchmark::State& state, int clients, int pings) {
  insitu::daemon::ServerOptions o;
  o.port = 0;
  o.results_dir = (std::filesystem::temp_directory_path() / "insitu_socket_bench").string();
  insitu::daemon::Server server(o);
  if (!server.Start().ok()) {
    state.SkipWithError("server did not start");
    return;
  }
  std::vector<double> all;
  int answered = 0;
  for (auto _ : state) {
    std::mutex m;
    std::atomic<int> ok{0};
    std::vector<std::thread> threads;
    for (int c = 0; c < clients; ++c) {
      threads.emplace_back([&] {
        std::vector<double> lat;
        ok += PingLoop(server.port(), pings, &lat);
        std::lock_guard<std::mutex> lock(m);
        all.insert(all.end(), lat.begin(), lat.end());
      });
    }
    for (auto& t : threads) t.join();
    answered = ok.load();
  }
  state.counters["answered"] = answered;
  state.counters["asked"] = clients * pings;
  state.counters["p50_us"] = Percentile(all, 0.50);
  state.counters["p99_us"] = Percentile(all, 0.99);
  std::printf("%d clients x %d pings: %d of %d answered, latency p50 %.0f us, p99 %.0f us\n",
              clients, pings, answered, clients * pings, Percentile(all, 0.5),
              Percentile(all, 0.99));
}

void BM_OneClient(benchmark::State& state) { Run(state, 1, 100); }
void BM_HundredClients(benchmark::State& state) { Run(state, 100, 100); }
BENCHMARK(BM_OneClient)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_HundredClients)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
