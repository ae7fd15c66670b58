// One phase of a running job, told both ways: a log line at most every second (core Progress)
// and RunOptions::progress at most every 0.2 s, with the first and last updates always sent.
#pragma once

#include <chrono>
#include <string>

#include "insitu/core/log.h"
#include "insitu/job/runner.h"

namespace insitu::job {

class PhaseProgress {
 public:
  PhaseProgress(const RunOptions& options, std::string phase, std::string unit, double total)
      : options_(options),
        log_("job", phase + ": " + unit, static_cast<int>(total)),
        phase_(std::move(phase)),
        unit_(std::move(unit)),
        total_(total) {
    Send(0.0);
  }

  void Update(double done) {
    log_.Update(static_cast<int>(done));
    const auto now = std::chrono::steady_clock::now();
    if (done < total_ && now - last_ < std::chrono::milliseconds(200)) return;
    last_ = now;
    Send(done);
  }

 private:
  void Send(double done) {
    if (options_.progress) options_.progress({phase_, done, total_, unit_});
  }

  const RunOptions& options_;
  Progress log_;
  std::string phase_, unit_;
  double total_;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace insitu::job
