// How a job's phases fail (internal to the job module). A job reads as a short list of named
// phases, each returning Ok or the Status the job ends with: its message is the report's error
// as the operator reads it, its code the job's status (to the exit status and the daemon) for
// the jobs that keep a failure's own code.
#pragma once

#include <string>

#include "insitu/core/status.h"

namespace insitu::job {

// `cause` as a report tells it: `context` ("marking: ", or nothing), then the cause's code
// name and message ("marking: device_error: ..."); the cause's code kept.
inline Status PhaseFailure(const Status& cause, const std::string& context = "") {
  return Status(cause.code(), context + cause.ToString());
}

}  // namespace insitu::job
