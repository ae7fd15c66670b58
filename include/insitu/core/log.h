// One logging facade for the whole product (spdlog underneath), a category per module.
// Library code logs through insitu::Logger("sim") and never writes to std::cout.
#pragma once

#include <memory>
#include <string>

#include <spdlog/spdlog.h>

namespace insitu {

// The logger of one module ("sim", "vision", "job", ...); created on first use, writes to stderr.
std::shared_ptr<spdlog::logger> Logger(const std::string& category);

// Sets the level of every insitu logger ("trace", "debug", "info", "warn", "error", "off").
void SetLogLevel(const std::string& level);

// Progress of long work ("scan 12/57 lines"): a line at info level at most every
// `min_interval_s`, plus the last one.
class Progress {
 public:
  Progress(std::string category, std::string what, int total, double min_interval_s = 1.0);
  void Update(int done);

 private:
  std::string category_;
  std::string what_;
  int total_;
  double min_interval_s_;
  double start_s_;
  double last_s_ = -1e9;
};

}  // namespace insitu
