#include "insitu/daemon/confine.h"

#include <filesystem>
#include <system_error>

namespace insitu::daemon {
namespace {

namespace fs = std::filesystem;

bool EndsWith(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

}  // namespace

Result<std::string> JobPathInside(const std::string& jobs_dir, const std::string& requested) {
  const fs::path p(requested);
  if (requested.empty()) return InvalidArgument("job: an empty path");
  if (p.is_absolute()) {
    return InvalidArgument("job: '" + requested +
                           "' is an absolute path; name a job file inside the daemon's jobs "
                           "folder, relative to it");
  }
  for (const fs::path& part : p) {
    if (part == "..") {
      return InvalidArgument("job: '" + requested +
                             "' leaves the daemon's jobs folder (a '..' in it)");
    }
  }
  // Links followed: a link inside the folder that points out of it is refused too.
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(fs::absolute(jobs_dir), ec);
  const fs::path full = fs::weakly_canonical(fs::absolute(fs::path(jobs_dir) / p), ec);
  if (ec) return InvalidArgument("job: '" + requested + "' cannot be resolved");
  const auto [end, rest] = std::mismatch(root.begin(), root.end(), full.begin(), full.end());
  if (end != root.end()) {
    return InvalidArgument("job: '" + requested + "' leaves the daemon's jobs folder (a link)");
  }
  return full.string();
}

Status CheckSetKeys(const std::vector<std::string>& sets) {
  for (const std::string& s : sets) {
    const std::string key = s.substr(0, s.find('='));
    const size_t dot = key.rfind('.');
    const std::string last = dot == std::string::npos ? key : key.substr(dot + 1);
    const bool names_file = last == "file" || EndsWith(last, "_file") || EndsWith(last, "_dir") ||
                            last == "calibration" || last == "correction" ||
                            last == "model_extension" || last == "baseline" || last == "world" ||
                            last == "base" || key == "output" || key.rfind("output.", 0) == 0;
    if (names_file) {
      return InvalidArgument("set: '" + key +
                             "' names a file; over the daemon a job reads the files its job "
                             "file names and writes under the daemon's results folder");
    }
  }
  return Status::Ok();
}

}  // namespace insitu::daemon
