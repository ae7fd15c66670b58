// The daemon's jobs: one at a time on the machine, on one worker thread. A run that comes while
// another job runs is refused, or queued when the daemon is configured to queue. Every job's
// life goes to the results store (queued, running, then done, faulted or cancelled) and out
// as events: `job` when it is queued, starts and ends, `progress` while it runs.
//
// A queued job starts only after the one before it ended done: the queue re-arms the machine
// for it (the operator armed it for the queue) and starts it. A fault or a cancel ends the
// queue: every job still waiting is recorded cancelled ("not run: ..."), never started on a
// machine in an unknown state.
//
// A job on a cell whose operator is a person asks them through the daemon: a `prompt` event
// (prompt_id, job_id, request) that `status` also shows while it waits, answered by `ack` from
// any authenticated client (done, or abort). Cancelling the job ends the wait.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "insitu/core/status.h"
#include "insitu/daemon/machine_state.h"
#include "insitu/daemon/results.h"
#include "insitu/job/job_file.h"

namespace insitu::daemon {

struct QueueOptions {
  bool queue = false;  // false: a run while a job runs is refused
  int max_queued = 8;  // waiting jobs at most (queue: true)
};

// What Submit did: the job's id and its place (0: it started now; k: k-th in the queue).
struct Submitted {
  std::string id;
  std::string kind;
  int position = 0;
};

class JobQueue {
 public:
  // emit(event, fields) is called from the caller's and the worker's threads; it must only
  // hand the event on (the server posts it to its io thread).
  using EmitFn = std::function<void(const std::string& event, nlohmann::json fields)>;

  JobQueue(StateMachine* state, ResultsStore* store, QueueOptions options, EmitFn emit);
  ~JobQueue();
  JobQueue(const JobQueue&) = delete;
  JobQueue& operator=(const JobQueue&) = delete;

  // Starts the job on an armed machine, or queues it behind the running one. Errors:
  // failed_precondition (not armed; busy and not queueing; the queue is full), device_error
  // (the results store cannot record it).
  Result<Submitted> Submit(job::LoadedJob job);
  // Cancels the running job (id empty or its id: the job stops at its next check, a marking
  // list within one head tick) or takes a queued one out of the queue. Returns the id.
  // Errors: failed_precondition (nothing runs), not_found (no such running or queued job).
  Result<std::string> Cancel(const std::string& id);
  // Answers the running job's prompt `prompt_id`: done (the operator did what it asks) or not
  // (abort: the job ends cancelled). Errors: failed_precondition (no prompt waits), not_found
  // (prompt_id is not the waiting one's: an answer to an earlier step never confirms this one).
  Status Ack(int prompt_id, bool done);
  // The running job and its last progress, the prompt waiting for the operator, and the
  // queue, for `status`.
  nlohmann::json Snapshot() const;
  // Cancels the running job, ends the queue, waits for the worker. Idempotent.
  void Stop();

 private:
  struct Entry {
    job::LoadedJob job;
    JobRecord record;
  };
  void Work();
  void RunOne(const Entry& entry);
  // The running job's question to the operator: emits it and waits for Ack or a cancel.
  Status AskPerson(const std::string& job_id, const std::string& request);
  // Under mutex_: records every waiting job cancelled with `reason` and tells it.
  void DropQueueLocked(const std::string& reason);

  StateMachine* state_;
  ResultsStore* store_;
  QueueOptions options_;
  EmitFn emit_;

  mutable std::mutex mutex_;
  std::mutex stop_mutex_;
  std::condition_variable wake_;
  std::deque<Entry> queue_;
  bool busy_ = false;  // a job is running (or about to, on the worker)
  bool finished_ = false;  // ... or has just ended, its outcome being recorded
  bool stopping_ = false;
  std::string running_id_, running_kind_;
  nlohmann::json progress_;  // the running job's last progress event, or null
  std::atomic<bool> cancel_{false};
  enum class Answer { kNone, kWaiting, kDone, kAborted };
  std::condition_variable prompt_wake_;
  Answer answer_ = Answer::kNone;
  int prompt_seq_ = 0;
  nlohmann::json prompt_;  // the waiting prompt, or null
  std::thread worker_;
};

}  // namespace insitu::daemon
