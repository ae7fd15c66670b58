// Runs a loaded job file: reads its sections strictly, brings up the machine named by
// `machine.backend`, runs, writes DIR/report.json and the job's artifacts.
//
// Errors before anything runs (bad job file, calibration that does not match the machine)
// come back as a Status and write nothing. A failure while running writes a report with
// "ok": false and the error, keeping whatever artifacts were already saved.
#pragma once

#include <atomic>
#include <string>

#include "insitu/core/status.h"
#include "insitu/job/job_file.h"
#include "insitu/job/report.h"

namespace insitu::job {

struct RunOptions {
  std::string out_dir = "insitu-out";
  const std::atomic<bool>* cancel = nullptr;
};

// Job kinds this build runs.
std::vector<std::string> JobKinds();

Result<Report> RunJob(const LoadedJob& job, const RunOptions& options);

}  // namespace insitu::job
