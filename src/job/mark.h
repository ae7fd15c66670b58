// The mark job (job: mark): scan the part where it lies, place a pattern on the measured
// surface, emit the 3D galvo list and mark it (seed 000 sec. 2.4, 3.3).
#pragma once

#include "insitu/job/runner.h"

namespace insitu::job {

Result<Report> RunMarkJob(const LoadedJob& job, const RunOptions& options);
// Reads every section as RunMarkJob does, touching nothing.
Status CheckMarkJob(const LoadedJob& job);

}  // namespace insitu::job
