// Groove inspection (seed 002): the inspect_grooves job engraves a design's contours into a
// clamped panel's maskant (at fixture coordinates, or registered on the scanned part) and
// inspects them with the line profiler on its axis: each profile's groove (centre, width,
// depth), the centres in the workpiece frame of the panel's tooling holes, clustered, matched to
// the design's contours and compared (offset, scale, local error). The calibrate_profiler job
// calibrates the profiler's mounting on its block and writes the mount file inspections read.
#pragma once

#include "insitu/job/runner.h"

namespace insitu::job {

Result<Report> RunInspectGroovesJob(const LoadedJob& job, const RunOptions& options);
Status CheckInspectGroovesJob(const LoadedJob& job);

Result<Report> RunCalibrateProfilerJob(const LoadedJob& job, const RunOptions& options);
Status CheckCalibrateProfilerJob(const LoadedJob& job);

}  // namespace insitu::job
