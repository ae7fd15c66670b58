// What every scanning job (scan, accuracy, mark) reads and brings up: the machine, the scan,
// camera, extraction and reconstruction sections, and the calibration checked against the
// camera. Internal to the job module.
#pragma once

#include <functional>
#include <string>

#include "insitu/calib/calibration.h"
#include "insitu/core/config.h"
#include "insitu/hw/cell.h"
#include "insitu/inspect/insert.h"
#include "insitu/inspect/step_gauge.h"
#include "insitu/job/job_file.h"
#include "insitu/job/runner.h"
#include "insitu/job/scan.h"
#include "insitu/vision/stripe.h"

namespace insitu::job {

struct ScanJobSpec {
  MachineSpec machine;
  ScanOptions scan;
  vision::StripeOptions extraction;
  int method = 1;
  std::string artifact;  // "", step_gauge or insert
  inspect::StepGaugeSpec gauge;
  inspect::InsertSpec insert;
  bool save_frames = false;
};

// Reads the common sections strictly; `extra` reads the job's own sections from the same
// root reader before it is finished (unknown keys are refused). Fills `machine` with the
// backend and, for the simulator, the world (with world_changes and --set applied).
Status ReadScanJob(const LoadedJob& job, ScanJobSpec* spec, hw::MachineConfig* machine,
                   const std::function<void(ConfigReader&)>& extra = {});

// The `artifact:` section (step_gauge or insert), when present.
void ReadArtifact(ConfigReader& r, ScanJobSpec* spec);

// What every job that scans reports of its scan: how the columns came out (valid, saturated,
// without a stripe, two peaks, too wide), the exposure (and auto exposure's pre-shots), the
// camera's band, trigger and frame rate, the machine time; warnings when saturated columns
// matter (over 1 % of the lit ones) or the band could not be used.
void ReportScanLight(const ScanStats& stats, Report* report);

struct ScanMachine {
  hw::Machine machine;
  calib::CalibrationSet calibration;
};

// Loads the calibration, brings up the cell (its scan head and side camera, and the roles in
// `more`), refuses a calibration for another camera.
Result<ScanMachine> BringUp(const LoadedJob& job, const ScanJobSpec& spec,
                            const hw::MachineConfig& config, const RunOptions& options,
                            std::initializer_list<hw::Role> more = {});

}  // namespace insitu::job
