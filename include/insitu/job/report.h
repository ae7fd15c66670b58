// report.json, the record every job leaves (format in CONTRACT.md):
// { "job", "ok", "started", "elapsed_s", "metrics", "artifacts", "warnings" } (+ "error" when
// the job failed). Metric names carry their unit.
#pragma once

#include <chrono>
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
  // Further top-level keys with their values as JSON text (a diagnosis's cause, effects, ...).
  std::map<std::string, std::string> extra_json;
};

std::string NowIso8601();
// Writes DIR/report.json atomically.
Status WriteReport(const Report& report, const std::string& dir);

// Starts a job's report: creates `dir` (not_found naming it if it cannot be made), names the
// job and stamps its start.
// `warnings` start the report's (the cell's: a dry run's simulated devices).
Result<Report> StartReport(const std::string& job_kind, const std::string& dir,
                           const std::vector<std::string>& warnings = {});

// Ends a job's report: sets ok, error and the elapsed time since `start`, writes it to `dir`.
// Returns the report, or for a failed job `failure` with the error (the report is on disk
// either way).
Result<Report> FinishReport(Report& report, bool ok, const std::string& error,
                            std::chrono::steady_clock::time_point start, const std::string& dir,
                            StatusCode failure);

}  // namespace insitu::job
