#include "daemon/job_queue.h"

#include <algorithm>
#include <utility>

#include "insitu/core/log.h"
#include "insitu/job/runner.h"

namespace insitu::daemon {

JobQueue::JobQueue(StateMachine* state, ResultsStore* store, QueueOptions options, EmitFn emit)
    : state_(state), store_(store), options_(options), emit_(std::move(emit)) {
  worker_ = std::thread([this] { Work(); });
}

JobQueue::~JobQueue() { Stop(); }

Result<Submitted> JobQueue::Submit(job::LoadedJob job) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (stopping_) return FailedPrecondition("the daemon is stopping");
  if (busy_) {
    if (!options_.queue) {
      return FailedPrecondition("job " + running_id_ +
                                " is running: one job at a time (this daemon does not queue)");
    }
    if (static_cast<int>(queue_.size()) >= options_.max_queued) {
      return FailedPrecondition("the queue is full (" + std::to_string(options_.max_queued) +
                                " jobs wait)");
    }
    INSITU_ASSIGN_OR_RETURN(JobRecord record, store_->Begin(job.kind, /*queued=*/true));
    queue_.push_back({std::move(job), record});
    const int position = static_cast<int>(queue_.size());
    emit_(
        "job",
        {{"job_id", record.id}, {"job", record.job}, {"status", "queued"}, {"position", position}});
    return Submitted{record.id, record.job, position};
  }
  INSITU_RETURN_IF_ERROR(state_->Start());
  auto record = store_->Begin(job.kind);
  if (!record.ok()) {
    (void)state_->Finish(JobOutcome::kFaulted, record.status().message());
    return record.status();
  }
  busy_ = true;
  finished_ = false;
  cancel_ = false;
  running_id_ = record->id;
  running_kind_ = record->job;
  progress_ = nullptr;
  // At the front: the worker takes it next, before anything queued after it.
  queue_.push_front({std::move(job), *record});
  emit_("job", {{"job_id", record->id}, {"job", record->job}, {"status", "running"}});
  wake_.notify_all();
  return Submitted{record->id, record->job, 0};
}

Result<std::string> JobQueue::Cancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (busy_ && finished_ && (id.empty() || id == running_id_)) {
    return FailedPrecondition("job " + running_id_ + " has just ended");
  }
  if (busy_ && (id.empty() || id == running_id_)) {
    cancel_ = true;
    prompt_wake_.notify_all();
    return running_id_;
  }
  if (id.empty()) return FailedPrecondition("no job is running");
  // The running job is the worker's (front) entry while busy; queued ones come after it.
  const size_t first_queued = busy_ && !queue_.empty() && queue_.front().record.id == running_id_;
  for (size_t i = first_queued; i < queue_.size(); ++i) {
    if (queue_[i].record.id != id) continue;
    (void)store_->Finish(id, "cancelled", "cancelled before it ran");
    emit_("job", {{"job_id", id}, {"status", "cancelled"}, {"reason", "cancelled before it ran"}});
    queue_.erase(queue_.begin() + static_cast<std::ptrdiff_t>(i));
    return id;
  }
  return NotFound("no running or queued job " + id);
}

nlohmann::json JobQueue::Snapshot() const {
  std::lock_guard<std::mutex> lock(mutex_);
  nlohmann::json queued = nlohmann::json::array();
  for (const Entry& e : queue_) {
    if (busy_ && e.record.id == running_id_) continue;
    queued.push_back(e.record.id);
  }
  nlohmann::json out = {{"queued", queued}};
  if (busy_) {
    out["job_id"] = running_id_;
    out["job"] = running_kind_;
    out["progress"] = progress_;
    if (!prompt_.is_null()) out["prompt"] = prompt_;
  }
  return out;
}

Status JobQueue::Ack(int prompt_id, bool done) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (answer_ != Answer::kWaiting) return FailedPrecondition("no prompt waits for an answer");
  const int waiting = prompt_["prompt_id"].get<int>();
  if (prompt_id != waiting) {
    return NotFound("prompt " + std::to_string(prompt_id) + " is not the one waiting (" +
                    std::to_string(waiting) + ")");
  }
  answer_ = done ? Answer::kDone : Answer::kAborted;
  prompt_wake_.notify_all();
  return Status::Ok();
}

Status JobQueue::AskPerson(const std::string& job_id, const std::string& request) {
  std::unique_lock<std::mutex> lock(mutex_);
  prompt_ = {{"prompt_id", ++prompt_seq_}, {"job_id", job_id}, {"request", request}};
  answer_ = Answer::kWaiting;
  emit_("prompt", prompt_);
  Logger("daemon")->info("job {} asks the operator: {}", job_id, request);
  prompt_wake_.wait(lock, [this] { return answer_ != Answer::kWaiting || cancel_.load(); });
  const Answer answer = answer_;
  const int id = prompt_["prompt_id"].get<int>();
  answer_ = Answer::kNone;
  prompt_ = nullptr;
  emit_("prompt", {{"prompt_id", id}, {"job_id", job_id},
                   {"answer", answer == Answer::kDone      ? "done"
                              : answer == Answer::kAborted ? "abort"
                                                           : "cancelled"}});
  if (answer == Answer::kDone) return Status::Ok();
  return Status(StatusCode::kCancelled, answer == Answer::kAborted
                                            ? "the operator aborted at: " + request
                                            : "cancelled while waiting for the operator");
}

void JobQueue::Stop() {
  std::lock_guard<std::mutex> stop(stop_mutex_);  // two stoppers: one joins, one waits
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    cancel_ = true;  // a running job stops at its next check; its state is saved
    wake_.notify_all();
    prompt_wake_.notify_all();
  }
  if (worker_.joinable()) worker_.join();
}

void JobQueue::DropQueueLocked(const std::string& reason) {
  for (const Entry& e : queue_) {
    (void)store_->Finish(e.record.id, "cancelled", reason);
    emit_("job", {{"job_id", e.record.id}, {"status", "cancelled"}, {"reason", reason}});
  }
  queue_.clear();
}

void JobQueue::Work() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stopping_ || busy_; });
    if (!busy_) {  // stopping with nothing running
      DropQueueLocked("not run: the daemon stopped");
      return;
    }
    const Entry entry = std::move(queue_.front());
    queue_.pop_front();
    lock.unlock();
    RunOne(entry);
    lock.lock();
    progress_ = nullptr;
    const MachineState after = state_->state();
    if (stopping_) {
      busy_ = false;
      DropQueueLocked("not run: the daemon stopped");
      return;
    }
    if (queue_.empty()) {
      busy_ = false;
      continue;
    }
    if (after != MachineState::kDone) {
      busy_ = false;
      DropQueueLocked("not run: the job before it (" + entry.record.id + ") ended " +
                      StateName(after));
      continue;
    }
    const Status next = state_->StartNext();
    const Status started = next.ok() ? store_->Started(queue_.front().record.id) : next;
    if (!started.ok()) {
      if (next.ok()) (void)state_->Finish(JobOutcome::kFaulted, started.message());
      busy_ = false;
      DropQueueLocked("not run: " + started.message());
      continue;
    }
    cancel_ = false;
    finished_ = false;
    running_id_ = queue_.front().record.id;
    running_kind_ = queue_.front().record.job;
    emit_("job", {{"job_id", running_id_}, {"job", running_kind_}, {"status", "running"}});
  }
}

void JobQueue::RunOne(const Entry& entry) {
  const JobRecord& rec = entry.record;
  job::RunOptions run;
  run.out_dir = rec.dir;
  run.cancel = &cancel_;
  run.confine_writes = true;  // everything under the job's results folder
  run.progress = [this, id = rec.id](const job::JobProgress& p) {
    nlohmann::json fields = {
        {"job_id", id}, {"phase", p.phase}, {"done", p.done}, {"total", p.total}, {"unit", p.unit}};
    {
      std::lock_guard<std::mutex> lock(mutex_);
      progress_ = fields;
    }
    emit_("progress", std::move(fields));
  };
  run.ask_person = [this, id = rec.id](const std::string& request) {
    return AskPerson(id, request);
  };
  Logger("daemon")->info("job {} ({}) starts", rec.id, rec.job);
  const auto report = job::RunJob(entry.job, run);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    finished_ = true;  // a cancel from now on has nothing to stop
  }
  const bool cancelled =
      cancel_.load() || (!report.ok() && report.status().code() == StatusCode::kCancelled);
  const std::string status = report.ok() && report->ok ? "done"
                             : cancelled               ? "cancelled"
                                                       : "faulted";
  const std::string reason = status == "done" ? ""
                             : report.ok()    ? report->error
                                              : report.status().message();
  (void)store_->Finish(rec.id, status, reason);
  (void)state_->Finish(status == "done"        ? JobOutcome::kDone
                       : status == "cancelled" ? JobOutcome::kCancelled
                                               : JobOutcome::kFaulted,
                       reason);
  Logger("daemon")->info("job {} {}{}{}", rec.id, status, reason.empty() ? "" : ": ", reason);
  emit_("job", {{"job_id", rec.id}, {"status", status}, {"reason", reason}});
}

}  // namespace insitu::daemon
