// Bringing up a job's cell: the front end's way to reach the operator goes to the cell, and
// every role the job needs must have a device before anything moves.
#pragma once

#include <initializer_list>
#include <utility>

#include "insitu/hw/cell.h"
#include "insitu/job/job_file.h"
#include "insitu/job/runner.h"

namespace insitu::job {

// Errors: the cell's own (a device that cannot be opened, by role); failed_precondition naming
// the first role in `needs` the cell has no device for.
inline Result<hw::Machine> OpenCell(hw::MachineConfig config, const RunOptions& options,
                                    std::initializer_list<hw::Role> needs, const LoadedJob& job) {
  config.ask_person = options.ask_person;
  INSITU_ASSIGN_OR_RETURN(hw::Machine machine, hw::CreateMachine(config));
  INSITU_RETURN_IF_ERROR(machine.Require(needs, job.path + ": the " + job.kind + " job"));
  return machine;
}

}  // namespace insitu::job
