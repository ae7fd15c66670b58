// libFuzzer target for a daemon run request's `set`: whatever JSON a client sends, a `set`
// insitud accepts (daemon::CheckSetKeys) and applies to a job (ConfigNode::Set, as the job
// loader does) never changes, adds or removes a key that names a file or says where a job
// writes (replacing a whole section by a number may drop one: the job then fails by name, and
// nothing is read or written elsewhere). Input: the request's `set` object as JSON text.
#include <cstdint>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "insitu/core/config.h"
#include "insitu/daemon/confine.h"

namespace {

// A job with files to read and to write, as the shipped ones have.
constexpr char kJob[] = R"(job: diagnose_machine
machine:
  backend: sim
  calibration: ../../out/calib/machine.yaml
world: ../worlds/default.yaml
design:
  file: ../patterns/skin_pockets.dxf
head:
  correction: table.csv
  model_extension: ext.yaml
diagnosis:
  baseline: base.csv
  record_baseline: false
profiler:
  mount_file: mount.yaml
  block:
    file: block.yaml
items:
  - pattern:
      kind: svg
      file: plate.svg
output:
  calibration: ../../out/calib/machine.yaml
scan:
  x_start_mm: -3
)";

// Every scalar under a key that names a file or where a job writes, by dotted path.
void Guarded(const insitu::ConfigNode& node, const std::string& path,
             std::map<std::string, std::string>* out) {
  if (node.IsMap()) {
    for (const std::string& k : node.Keys()) {
      const std::string key = path.empty() ? k : path + "." + k;
      const insitu::ConfigNode child = node.Child(k);
      if ((insitu::daemon::NamesAFile(key) || insitu::daemon::ForbiddenSetKey(key)) &&
          !child.IsMap() && !child.IsSequence()) {
        (*out)[key] = child.Dump();
      }
      Guarded(child, key, out);
    }
  } else if (node.IsSequence()) {
    for (size_t i = 0; i < node.size(); ++i) {
      Guarded(node.At(i), path + "[" + std::to_string(i) + "]", out);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto set = nlohmann::json::parse(data, data + size, nullptr, /*allow_exceptions=*/false);
  if (!set.is_object()) return 0;
  std::vector<std::string> sets;
  for (auto it = set.begin(); it != set.end(); ++it) {
    const nlohmann::json& v = it.value();
    sets.push_back(it.key() + "=" + (v.is_string() ? v.get<std::string>() : v.dump()));
  }
  if (!insitu::daemon::CheckSetKeys(sets).ok()) return 0;
  auto base = insitu::ConfigNode::Parse(kJob, "job.yaml");
  if (!base.ok()) std::abort();
  insitu::ConfigNode job = base->Clone();
  for (const std::string& s : sets) {
    const size_t eq = s.find('=');
    (void)job.Set(s.substr(0, eq), eq == std::string::npos ? "" : s.substr(eq + 1));
  }
  std::map<std::string, std::string> before, after;
  Guarded(*base, "", &before);
  Guarded(job, "", &after);
  for (const auto& [key, value] : after) {
    const auto was = before.find(key);
    if (was == before.end() || was->second != value) std::abort();  // a set reached a file
  }
  return 0;
}
