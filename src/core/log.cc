#include "insitu/core/log.h"

#include <chrono>
#include <mutex>

#include <spdlog/sinks/stdout_color_sinks.h>

namespace insitu {
namespace {

std::mutex g_mutex;
spdlog::level::level_enum g_level = spdlog::level::info;

double NowSeconds() {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

}  // namespace

std::shared_ptr<spdlog::logger> Logger(const std::string& category) {
  std::lock_guard<std::mutex> lock(g_mutex);
  auto logger = spdlog::get(category);
  if (logger) return logger;
  logger = spdlog::stderr_color_mt(category);
  logger->set_pattern("[%H:%M:%S.%e] [%n] [%^%l%$] %v");
  logger->set_level(g_level);
  return logger;
}

void SetLogLevel(const std::string& level) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_level = spdlog::level::from_str(level);
  spdlog::apply_all([](const std::shared_ptr<spdlog::logger>& l) { l->set_level(g_level); });
}

Progress::Progress(std::string category, std::string what, int total, double min_interval_s)
    : category_(std::move(category)),
      what_(std::move(what)),
      total_(total),
      min_interval_s_(min_interval_s),
      start_s_(NowSeconds()) {}

void Progress::Update(int done) {
  const double now = NowSeconds();
  if (done < total_ && now - last_s_ < min_interval_s_) return;
  last_s_ = now;
  const double elapsed = now - start_s_;
  const double eta = done > 0 ? elapsed * (total_ - done) / done : 0.0;
  Logger(category_)->info("{} {}/{} ({:.0f}%), {:.1f} s elapsed, ~{:.1f} s left", what_, done,
                          total_, total_ > 0 ? 100.0 * done / total_ : 100.0, elapsed, eta);
}

}  // namespace insitu
