// Runs a loaded job file: reads its sections strictly, brings up the machine named by
// `machine.backend`, runs, writes DIR/report.json and the job's artifacts.
//
// Errors before anything runs (bad job file, calibration that does not match the machine)
// come back as a Status and write nothing. A failure while running writes a report with
// "ok": false and the error, keeping whatever artifacts were already saved.
#pragma once

#include <atomic>
#include <functional>
#include <string>

#include "insitu/core/status.h"
#include "insitu/job/job_file.h"
#include "insitu/job/report.h"

namespace insitu::job {

// How far a running job is: its phase ("scan", "mark", "board views", ...) and how much of
// that phase is done, in the phase's unit ("lines", "s" of list time, "views", ...).
struct JobProgress {
  std::string phase;
  double done = 0.0;
  double total = 0.0;
  std::string unit;
};

struct RunOptions {
  std::string out_dir = "insitu-out";
  // Set from another thread to stop the job: scans stop between lines, a marking list is
  // aborted by the head within one of its clock ticks (laser off), and the job ends cancelled.
  const std::atomic<bool>* cancel = nullptr;
  // Called on the job's thread when a phase starts, then at most about every 0.2 s, and when
  // it ends. May be empty.
  std::function<void(const JobProgress&)> progress;
  // How a cell with `machine.operator: person` asks them (hw::AskPerson): shows the request
  // and returns when done; cancelled when they refuse. Empty: such a cell does not come up.
  std::function<Status(const std::string& request)> ask_person;
  // A file the job file names for the job to write (output.calibration, output.mount_file, a
  // diagnosis baseline) goes into out_dir under its own name unless it is inside it already,
  // with a warning (insitud: everything a job writes goes under its results folder).
  bool confine_writes = false;
};

// Job kinds this build runs.
std::vector<std::string> JobKinds();

// Reads every section of the job strictly, as RunJob will, without bringing up the machine or
// writing anything: the errors RunJob would give before moving (unknown or bad keys, with
// file, line and key; an unknown kind). Pattern, calibration and table files are read by
// RunJob, before the machine moves.
// Also refused: a role the job needs (its scan head, a Z stage, ...) that its cell names no
// device for (failed_precondition, naming the role's key).
Status CheckJob(const LoadedJob& job);

Result<Report> RunJob(const LoadedJob& job, const RunOptions& options);

}  // namespace insitu::job
