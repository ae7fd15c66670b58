// report.json, the record every job leaves (format in CONTRACT.md):
// { "job", "ok", "started", "elapsed_s", "metrics", "artifacts", "warnings" } (+ "error" when
// the job failed). Metric names carry their unit.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::job {

struct Report {
  std::string job;
  bool ok = false;
  std::string started;  // ISO 8601, UTC
  double elapsed_s = 0.0;
  std::map<std::string, double> metrics;
  std::map<std::string, std::string> artifacts;  // name -> path relative to the report
  std::vector<std::string> warnings;
  std::string error;  // set when !ok
};

std::string NowIso8601();
// Writes DIR/report.json atomically.
Status WriteReport(const Report& report, const std::string& dir);

}  // namespace insitu::job
