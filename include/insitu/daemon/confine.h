// What a client of insitud may name: a job file inside the daemon's jobs folder (no absolute
// path, no `..`, no symbolic link out of it), and `set` overrides that change a job's settings
// but never redirect a file (the files a job reads and writes are the daemon's configuration's:
// its jobs, its cell's calibration, its results folder).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "insitu/core/config.h"
#include "insitu/core/status.h"

namespace insitu::daemon {

// The job file a run request names, inside `jobs_dir`. Errors: invalid_argument naming the
// request (an absolute path, a `..` component, a path that leaves the folder through a link),
// never the file's contents.
Result<std::string> JobPathInside(const std::string& jobs_dir, const std::string& requested);

// Refuses a `set` key that names a file: its last part `file`, ending in `_file` or `_dir`, or
// one of calibration, correction, model_extension, baseline, world, base; or under output.
// Errors: invalid_argument naming the key.
// Also refused: output.*, record_baseline and job (where and whether a job writes, its kind),
// and a value that is a section (a map, or text that reads as one) rather than a number, a word
// or a list of them.
Status CheckSetKeys(const std::vector<std::string>& sets);

// The rules themselves: a key whose last part names a file; a key a client may not set at all.
bool NamesAFile(const std::string& dotted_key);
bool ForbiddenSetKey(const std::string& dotted_key);

// An inline job (a run request's JSON) by the same rules, at any depth: a file key's value a
// path inside `jobs_dir`, nothing under output, no record_baseline. Errors name the key.
Status CheckInlineJob(const nlohmann::json& job, const std::string& jobs_dir,
                      const std::string& where = "");

// Where a job may read: inside one of `folders`, or exactly one of `files` (the daemon's own:
// its cell's calibration, its board's correction table).
struct ReadRoots {
  std::vector<std::string> folders;
  std::vector<std::string> files;
};

// True when `path` (links followed) lies inside one of the roots' folders or is one of its
// files.
bool InsideRoots(const std::string& path, const ReadRoots& roots);

// Every file `doc` names (a key NamesAFile gives, at any depth, a path or a list of them),
// resolved against `folder`, lies within `roots`; a world document's `base:` resolves against
// `folder` as well (pass the world file's). Errors: invalid_argument naming the key where it
// is written (file and line), never the file's contents. `skip_machine`: the doc's machine:
// section is replaced by the daemon's cell (its files are the cell's, in roots.files).
Status CheckReads(const ConfigNode& doc, const std::string& folder, const ReadRoots& roots,
                  bool skip_machine = false);

}  // namespace insitu::daemon
