// The diagnose_machine job (CONTRACT.md, "Machine diagnosis"): scans the known step gauge with
// the current calibration, at one or more stage heights, and diagnoses the whole cell against
// its model. Internal to the job module.
//
// The model of the cell is the calibration itself: a stripe pixel becomes a ray (the camera's
// intrinsics and its pose in the galvo frame), the ray meets the scan line's light plane (the
// head's map from command to chief rays), and the point lies on the gauge (its known step
// heights, on the stage plate at the stage's height). Each machine-domain effect is a change of
// that calibration, parametrised from zero (the machine as calibrated):
//   camera_pose        rx, ry, rz (mrad, about the camera's centre), tx, ty, tz (mm, galvo frame)
//   camera_distortion  dk1, dk2 (the lens's radial coefficients)
//   head_scale         s (1e-3: the field's size; objective focal length or galvo gain)
//   galvo_offset       ox, oy (mm: the field shifted; mirror zero offsets)
//   light_plane        tilt (mrad: every light plane turned about its line), pupil (mm: the exit
//                      pupil's height, so the planes lean by x / L otherwise)
//   stage_scale        s (1e-3: the stage's travel against its commands; needs two heights)
//   focus_scale        c (1e-3 / mm: the field's size against the dynamic focus, x += c z x;
//                      needs two heights, each pass focused on the gauge: diagnosis.refocus)
// The gauge's placement does not change the heights of a level gauge on the plate; it only
// decides which step a point is on (edges kept out by the margin). The residuals: each binned
// point's height minus its step's; where each line leaves a step's top at the gauge's ends,
// its y minus the end's (the gauge standing where it stood for the baseline); and each pointer
// spot parked on the plate, where the camera sees it minus where the field puts its command (x
// and y), which shows the field's shift along the lines. All less the baseline's (the machine
// as calibrated). fit::DiagnoseGroups selects the causes (BIC, and the held-out error over
// whole scan lines).
#pragma once

#include "insitu/core/status.h"
#include "insitu/job/job_file.h"
#include "insitu/job/report.h"
#include "insitu/job/runner.h"

namespace insitu::job {

Status CheckDiagnoseMachineJob(const LoadedJob& job);
Result<Report> RunDiagnoseMachineJob(const LoadedJob& job, const RunOptions& options);

}  // namespace insitu::job
