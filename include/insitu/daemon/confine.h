// What a client of insitud may name: a job file inside the daemon's jobs folder (no absolute
// path, no `..`, no symbolic link out of it), and `set` overrides that change a job's settings
// but never redirect a file (the files a job reads and writes are the daemon's configuration's:
// its jobs, its cell's calibration, its results folder).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

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

}  // namespace insitu::daemon
