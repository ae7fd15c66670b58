#include "insitu/daemon/confine.h"

#include <filesystem>
#include <system_error>

#include <nlohmann/json.hpp>

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
  if (requested.find('\0') != std::string::npos) return InvalidArgument("job: a NUL in the path");
  // Links followed: a link inside the folder that points out of it is refused too.
  std::error_code ec_root, ec_full;
  const fs::path root = fs::weakly_canonical(fs::absolute(jobs_dir), ec_root);
  const fs::path full = fs::weakly_canonical(fs::absolute(fs::path(jobs_dir) / p), ec_full);
  if (ec_root || root.empty()) return InvalidArgument("the daemon's jobs folder cannot be resolved");
  if (ec_full) return InvalidArgument("job: '" + requested + "' cannot be resolved");
  const auto [end, rest] = std::mismatch(root.begin(), root.end(), full.begin(), full.end());
  if (end != root.end()) {
    return InvalidArgument("job: '" + requested + "' leaves the daemon's jobs folder (a link)");
  }
  return full.string();
}

bool NamesAFile(const std::string& key) {
  const size_t dot = key.rfind('.');
  const std::string last = dot == std::string::npos ? key : key.substr(dot + 1);
  return last == "file" || EndsWith(last, "_file") || EndsWith(last, "_dir") ||
         last == "calibration" || last == "correction" || last == "model_extension" ||
         last == "baseline" || last == "world" || last == "base";
}

// Keys a client may not change at all: where a job writes (output), whether it writes beside
// the cell's calibration (record_baseline), and what kind of job it is.
bool ForbiddenSetKey(const std::string& key) {
  const size_t dot = key.rfind('.');
  const std::string last = dot == std::string::npos ? key : key.substr(dot + 1);
  return key == "output" || key.rfind("output.", 0) == 0 || last == "record_baseline" ||
         key == "job";
}

Status CheckSetKeys(const std::vector<std::string>& sets) {
  for (const std::string& s : sets) {
    const size_t eq = s.find('=');
    const std::string key = s.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : s.substr(eq + 1);
    if (NamesAFile(key) || ForbiddenSetKey(key)) {
      return InvalidArgument("set: '" + key +
                             "' names a file or where a job writes; over the daemon a job reads "
                             "the files its job file names and writes under the results folder");
    }
    // A value is a number, a word or a list of them: a map (or text that reads as one) would
    // replace a whole section, file keys and all. Judged as the reader will read it (YAML), and
    // on the text too, for anything YAML would take as structure.
    const size_t start = value.find_first_not_of(" \t");
    bool structured = start != std::string::npos &&
                      (value[start] == '{' || value.compare(start, 2, "- ") == 0 ||
                       value.find(": ") != std::string::npos || value.find(":\t") != std::string::npos ||
                       value.find('\n') != std::string::npos ||
                       (value[start] == '[' && value.find('{') != std::string::npos));
    const auto parsed = ConfigNode::Parse(value, "set");
    if (parsed.ok() && !parsed->IsScalar() && !parsed->IsNull()) {
      structured = structured || !parsed->IsSequence();
      for (size_t i = 0; parsed->IsSequence() && i < parsed->size(); ++i) {
        structured = structured || !parsed->At(i).IsScalar();
      }
    }
    if (structured) {
      return InvalidArgument("set: '" + key +
                             "' must be a number, a word or a list of them, not a section");
    }
  }
  return Status::Ok();
}

Status CheckInlineJob(const nlohmann::json& job, const std::string& jobs_dir,
                      const std::string& where) {
  if (job.is_object()) {
    for (auto it = job.begin(); it != job.end(); ++it) {
      const std::string key = where.empty() ? it.key() : where + "." + it.key();
      if (ForbiddenSetKey(key) && key != "job") {
        return InvalidArgument("job." + key + ": an inline job may not say where it writes");
      }
      if (NamesAFile(it.key()) && it.value().is_string()) {
        auto inside = JobPathInside(jobs_dir, it.value().get<std::string>());
        if (!inside.ok()) {
          return InvalidArgument("job." + key + ": " + inside.status().message().substr(5));
        }
      }
      INSITU_RETURN_IF_ERROR(CheckInlineJob(it.value(), jobs_dir, key));
    }
  } else if (job.is_array()) {
    for (size_t i = 0; i < job.size(); ++i) {
      INSITU_RETURN_IF_ERROR(CheckInlineJob(job[i], jobs_dir, where + "[" + std::to_string(i) + "]"));
    }
  }
  return Status::Ok();
}

bool InsideRoots(const std::string& path, const ReadRoots& roots) {
  std::error_code ec;
  const fs::path full = fs::weakly_canonical(fs::absolute(path), ec);
  if (ec) return false;
  for (const std::string& f : roots.files) {
    std::error_code ec_file;
    if (fs::weakly_canonical(fs::absolute(f), ec_file) == full && !ec_file) return true;
  }
  for (const std::string& d : roots.folders) {
    std::error_code ec_root;
    const fs::path root = fs::weakly_canonical(fs::absolute(d), ec_root);
    if (ec_root || root.empty()) continue;
    const auto [end, rest] = std::mismatch(root.begin(), root.end(), full.begin(), full.end());
    if (end == root.end()) return true;
  }
  return false;
}

namespace {

Status CheckPath(const ConfigNode& value, const std::string& folder, const ReadRoots& roots) {
  auto text = value.AsString();
  if (!text.ok() || text->empty()) return Status::Ok();  // the job's own reader says what is wrong
  // The path as the job opens it (job::ResolvePath: lexically normal, so a `..` after a link
  // cancels the link's name, not its target), then with its links followed.
  const fs::path p(*text);
  const std::string path = (p.is_absolute() ? p : fs::path(folder) / p).lexically_normal().string();
  if (InsideRoots(path, roots)) return Status::Ok();
  return InvalidArgument(value.Where() + ": '" + *text +
                         "' is outside the folders this daemon reads (read_roots)");
}

}  // namespace

Status CheckReads(const ConfigNode& doc, const std::string& folder, const ReadRoots& roots,
                  bool skip_machine) {
  if (doc.IsMap()) {
    for (const std::string& key : doc.Keys()) {
      if (key == "output") continue;  // what a job writes: under its results folder (runner.h)
      if (skip_machine && key == "machine") continue;
      const ConfigNode child = doc.Child(key);
      if (NamesAFile(key) && child.IsScalar()) {
        INSITU_RETURN_IF_ERROR(CheckPath(child, folder, roots));
      } else if (NamesAFile(key) && child.IsSequence()) {
        for (size_t i = 0; i < child.size(); ++i) {
          if (child.At(i).IsScalar()) INSITU_RETURN_IF_ERROR(CheckPath(child.At(i), folder, roots));
        }
      } else {
        INSITU_RETURN_IF_ERROR(CheckReads(child, folder, roots));
      }
    }
  } else if (doc.IsSequence()) {
    for (size_t i = 0; i < doc.size(); ++i) {
      INSITU_RETURN_IF_ERROR(CheckReads(doc.At(i), folder, roots));
    }
  }
  return Status::Ok();
}

}  // namespace insitu::daemon
