// Where a job writes a file its job file names (a calibration, a profiler mount, a diagnosis
// baseline): there, or, when the job runs confined (RunOptions::confine_writes, as insitud runs
// every job), in the job's own results folder under the same name, with a warning saying so.
#pragma once

#include <algorithm>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "insitu/job/runner.h"

namespace insitu::job {

inline std::string OutputPath(const std::string& path, const std::string& key,
                              const RunOptions& options, std::vector<std::string>* warnings) {
  namespace fs = std::filesystem;
  if (!options.confine_writes) return path;
  std::error_code ec_dir, ec_path;
  const fs::path dir = fs::weakly_canonical(fs::absolute(options.out_dir), ec_dir);
  const fs::path full = fs::weakly_canonical(fs::absolute(path), ec_path);
  if (!ec_dir && !ec_path) {
    const auto [end, rest] = std::mismatch(dir.begin(), dir.end(), full.begin(), full.end());
    if (end == dir.end()) return path;
  }
  // Prefixed: the job's own files (report.json, state.json, calibration.yaml) keep theirs.
  const std::string name = fs::path(path).filename().string();
  const std::string inside =
      (fs::path(options.out_dir) / ("output_" + (name.empty() ? "file" : name))).string();
  warnings->push_back(key + ": written to " + inside + ", not " + path +
                      " (a job run by insitud writes under its results folder only)");
  return inside;
}

}  // namespace insitu::job
