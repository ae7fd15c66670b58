// The calibrate job (job: calibrate). See docs/calibration.md.
#pragma once

#include "insitu/job/runner.h"

namespace insitu::job {

Result<Report> RunCalibrateJob(const LoadedJob& job, const RunOptions& options);

}  // namespace insitu::job
