#include "insitu/job/report.h"

#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "insitu/core/file.h"

namespace insitu::job {

std::string NowIso8601() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

Status WriteReport(const Report& report, const std::string& dir) {
  nlohmann::ordered_json j;
  j["job"] = report.job;
  j["ok"] = report.ok;
  j["started"] = report.started;
  j["elapsed_s"] = report.elapsed_s;
  nlohmann::ordered_json metrics = nlohmann::ordered_json::object();
  for (const auto& [name, value] : report.metrics) {
    // JSON has no NaN: an unmeasured metric is null, never a made-up number.
    if (std::isfinite(value)) {
      metrics[name] = value;
    } else {
      metrics[name] = nullptr;
    }
  }
  j["metrics"] = metrics;
  j["artifacts"] = report.artifacts;
  j["warnings"] = report.warnings;
  if (!report.ok) j["error"] = report.error;
  for (const auto& [key, text] : report.extra_json) {
    j[key] = nlohmann::ordered_json::parse(text, nullptr, /*allow_exceptions=*/false);
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  return WriteFileAtomically((std::filesystem::path(dir) / "report.json").string(),
                             j.dump(2) + "\n");
}

Result<Report> StartReport(const std::string& job_kind, const std::string& dir,
                           const std::vector<std::string>& warnings) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return NotFound("cannot create output folder " + dir + ": " + ec.message());
  Report report;
  report.job = job_kind;
  report.started = NowIso8601();
  report.warnings = warnings;
  return report;
}

Result<Report> FinishReport(Report& report, bool ok, const std::string& error,
                            std::chrono::steady_clock::time_point start, const std::string& dir,
                            StatusCode failure) {
  report.ok = ok;
  report.error = error;
  report.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  INSITU_RETURN_IF_ERROR(WriteReport(report, dir));
  if (!ok) return Status(failure, error);
  return report;
}

}  // namespace insitu::job
