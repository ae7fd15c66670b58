// The field_calibration job (job: field_calibration): the camera measures where the scan head
// really puts the beam, the machine fits its head and corrects itself (seeds 001 and 003).
// See docs/calibration.md, "Field calibration".
#pragma once

#include "insitu/job/runner.h"

namespace insitu::job {

Result<Report> RunFieldCalibrationJob(const LoadedJob& job, const RunOptions& options);
// Reads every section as RunFieldCalibrationJob does, touching nothing.
Status CheckFieldCalibrationJob(const LoadedJob& job);

}  // namespace insitu::job
