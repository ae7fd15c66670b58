// The daemon's results folder: one sub-folder per job (its report.json and artifacts, written
// by the job) plus the daemon's own state.json saying what became of the job. Every file the
// store writes is written atomically (a temporary file, then rename), so a reader never sees
// half of one. A job the daemon was running (or had queued) when it died (crash, kill, power)
// still says "running" ("queued") on disk; opening the store marks every such job
// "interrupted": never "done".
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::daemon {

struct JobRecord {
  std::string id;       // folder name: sortable, newest last ("20261123T164500Z-0003")
  std::string job;      // job kind
  std::string status;   // queued, running, done, faulted, cancelled, interrupted, unreadable
  std::string reason;   // the fault or cancel message; why unreadable
  std::string started;  // ISO 8601
  std::string finished;
  std::string dir;  // absolute folder of the job's files
};

class ResultsStore {
 public:
  // Creates the folder if needed and marks jobs left running by a dead daemon "interrupted".
  // Errors: not_found naming the folder when it cannot be made.
  static Result<ResultsStore> Open(const std::string& dir);

  ResultsStore(ResultsStore&&) noexcept;
  ResultsStore& operator=(ResultsStore&&) noexcept;

  // A new job folder with state "running" (or "queued"). Errors: device_error naming the file.
  Result<JobRecord> Begin(const std::string& job_kind, bool queued = false);
  // A queued job starts: "running", its start time now. Errors: not_found, device_error.
  Status Started(const std::string& id);
  // Its final state: status is done, faulted or cancelled. Errors: not_found (no such job),
  // invalid_argument (another status), device_error.
  Status Finish(const std::string& id, const std::string& status, const std::string& reason);
  // Every job, newest first. A folder whose state.json cannot be read is listed "unreadable".
  std::vector<JobRecord> List() const;
  // One job. Errors: not_found; invalid_argument for an id that is not a plain folder name.
  Result<JobRecord> Get(const std::string& id) const;

  const std::string& dir() const { return dir_; }
  int interrupted_at_open() const { return interrupted_; }

 private:
  explicit ResultsStore(std::string dir) : dir_(std::move(dir)) {}
  std::string dir_;
  int interrupted_ = 0;
  int counter_ = 0;
  std::unique_ptr<std::mutex> mutex_ = std::make_unique<std::mutex>();
};

}  // namespace insitu::daemon
