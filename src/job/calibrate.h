// The calibrate job (job: calibrate). See docs/calibration.md.
#pragma once

#include "insitu/job/runner.h"

namespace insitu::job {

Result<Report> RunCalibrateJob(const LoadedJob& job, const RunOptions& options);
// Reads every section as RunCalibrateJob does, touching nothing.
Status CheckCalibrateJob(const LoadedJob& job);

}  // namespace insitu::job
