#include "insitu/daemon/results.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "insitu/core/file.h"

namespace insitu::daemon {
namespace {

namespace fs = std::filesystem;

std::string Now(const char* format) {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, format, &tm);
  return buf;
}

Status WriteState(const JobRecord& r) {
  const nlohmann::json j = {{"id", r.id},         {"job", r.job},         {"status", r.status},
                            {"reason", r.reason}, {"started", r.started}, {"finished", r.finished}};
  return WriteFileAtomically((fs::path(r.dir) / "state.json").string(), j.dump(2) + "\n");
}

JobRecord ReadState(const fs::path& folder) {
  JobRecord r;
  r.id = folder.filename().string();
  r.dir = fs::absolute(folder).string();
  std::ifstream f(folder / "state.json");
  std::stringstream ss;
  ss << f.rdbuf();
  const nlohmann::json j = nlohmann::json::parse(ss.str(), nullptr, false);
  const auto str = [&](const char* key) {
    return j.is_object() && j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : "";
  };
  r.status = str("status");
  if (!f || j.is_discarded() || r.status.empty()) {
    r.status = "unreadable";
    r.reason = "state.json missing or malformed";
    return r;
  }
  r.job = str("job");
  r.reason = str("reason");
  r.started = str("started");
  r.finished = str("finished");
  return r;
}

bool PlainName(const std::string& id) {
  return !id.empty() && id.size() < 100 && id.find_first_of("/\\") == std::string::npos &&
         id != "." && id != "..";
}

}  // namespace

ResultsStore::ResultsStore(ResultsStore&&) noexcept = default;
ResultsStore& ResultsStore::operator=(ResultsStore&&) noexcept = default;

Result<ResultsStore> ResultsStore::Open(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) return NotFound("cannot make the results folder " + dir);
  ResultsStore store(fs::absolute(dir).string());
  for (JobRecord& r : store.List()) {
    if (r.status != "running" && r.status != "queued") continue;
    // Nobody runs it now: the daemon that did (or would have) died with it.
    r.reason = r.status == "running" ? "the daemon stopped while the job was running"
                                     : "the daemon stopped while the job was queued; it never ran";
    r.status = "interrupted";
    r.finished = Now("%Y-%m-%dT%H:%M:%SZ");
    INSITU_RETURN_IF_ERROR(WriteState(r));
    ++store.interrupted_;
  }
  return store;
}

Result<JobRecord> ResultsStore::Begin(const std::string& job_kind, bool queued) {
  std::lock_guard<std::mutex> lock(*mutex_);
  JobRecord r;
  r.job = job_kind;
  r.status = queued ? "queued" : "running";
  r.started = Now("%Y-%m-%dT%H:%M:%SZ");
  // Unique even within a second and across restarts: the first free counter.
  const std::string stamp = Now("%Y%m%dT%H%M%SZ");
  for (;;) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s-%04d", stamp.c_str(), ++counter_);
    const fs::path folder = fs::path(dir_) / buf;
    std::error_code ec;
    if (fs::create_directory(folder, ec)) {
      r.id = buf;
      r.dir = folder.string();
      break;
    }
    if (ec)
      return Status(StatusCode::kDeviceError,
                    "cannot make " + folder.string() + ": " + ec.message());
  }
  INSITU_RETURN_IF_ERROR(WriteState(r));
  return r;
}

Status ResultsStore::Started(const std::string& id) {
  std::lock_guard<std::mutex> lock(*mutex_);
  INSITU_ASSIGN_OR_RETURN(JobRecord r, Get(id));
  r.status = "running";
  r.started = Now("%Y-%m-%dT%H:%M:%SZ");
  return WriteState(r);
}

Status ResultsStore::Finish(const std::string& id, const std::string& status,
                            const std::string& reason) {
  if (status != "done" && status != "faulted" && status != "cancelled") {
    return InvalidArgument("a job ends done, faulted or cancelled, not " + status);
  }
  std::lock_guard<std::mutex> lock(*mutex_);
  INSITU_ASSIGN_OR_RETURN(JobRecord r, Get(id));
  r.status = status;
  r.reason = reason;
  r.finished = Now("%Y-%m-%dT%H:%M:%SZ");
  return WriteState(r);
}

std::vector<JobRecord> ResultsStore::List() const {
  std::vector<JobRecord> out;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    if (entry.is_directory()) out.push_back(ReadState(entry.path()));
  }
  std::sort(out.begin(), out.end(),
            [](const JobRecord& a, const JobRecord& b) { return a.id > b.id; });
  return out;
}

Result<JobRecord> ResultsStore::Get(const std::string& id) const {
  if (!PlainName(id)) return InvalidArgument("\"" + id + "\" is not a job id");
  const fs::path folder = fs::path(dir_) / id;
  if (!fs::is_directory(folder)) return NotFound("no job " + id + " in " + dir_);
  return ReadState(folder);
}

}  // namespace insitu::daemon
