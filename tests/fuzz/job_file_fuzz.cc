// libFuzzer target for job files as the daemon receives them (LoadJobText): arbitrary YAML and
// --set overrides, with world files resolved against the shipped config/jobs folder, so
// world:, world_changes: and world.* sets reach the strict world reader. Nothing may crash,
// hang or throw, and every error must say where it comes from (the job's origin name, the
// world file, or the --set). Input: <set>\<job YAML text> (FuzzedDataProvider strings).
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "insitu/job/job_file.h"

namespace {

constexpr char kOrigin[] = "fuzz-job.yaml";

void Check(bool condition) {
  if (!condition) std::abort();
}

void CheckNamed(const insitu::Status& status) {
  if (status.ok()) return;
  const std::string& m = status.message();
  Check(m.find(kOrigin) != std::string::npos || m.find("--set") != std::string::npos ||
        m.find(".yaml") != std::string::npos);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider input(data, size);
  const std::string set = input.ConsumeRandomLengthString(128);
  const std::string text = input.ConsumeRemainingBytesAsString();
  std::vector<std::string> sets;
  if (!set.empty()) sets.push_back(set);

  auto loaded = insitu::job::LoadJobText(text, kOrigin, INSITU_SOURCE_DIR "/config/jobs", sets);
  if (!loaded.ok()) {
    CheckNamed(loaded.status());
    return 0;
  }
  // The header, the machine and the world, read strictly as every job kind reads them.
  insitu::ConfigReader r(loaded->root);
  insitu::job::MachineSpec machine;
  insitu::job::ReadJobHeader(r, *loaded, &machine);
  insitu::vision::StripeOptions stripe;
  if (r.Has("extraction")) insitu::job::ReadStripeOptions(r.Section("extraction"), &stripe);
  for (const std::string& key : loaded->root.Keys()) r.Skip(key);  // the kinds' own sections
  CheckNamed(r.Finish());
  insitu::hw::MachineConfig config;
  CheckNamed(insitu::job::MachineConfigFor(*loaded, machine, &config));
  return 0;
}
