// Job files: what an operator writes and `insitu run` executes.
//
// A job file is YAML with a `job:` kind and the sections that kind needs. `world:` (simulator
// backend) names a world file (config/worlds/); relative paths resolve against the job file's
// folder. `world_changes:` (a map shaped like the world file) changes the world for this job:
// the part on the stage, where it lies. `--set dotted.key=value` overrides any key of the job,
// and keys under `world.` go to the world document, so `--set world.camera.k1=-0.08` works. Every
// error names the file, the line and the key (or the --set that gave the value).
#pragma once

#include <string>
#include <vector>

#include "insitu/core/config.h"
#include "insitu/core/status.h"
#include "insitu/hw/cell.h"
#include "insitu/sim/world_options.h"
#include "insitu/vision/stripe.h"

namespace insitu::job {

struct LoadedJob {
  std::string kind;    // "scan", ...
  std::string path;    // the job file
  std::string folder;  // its folder, for relative paths
  ConfigNode root;     // the job document, --set applied
  ConfigNode world;    // the world document (undefined if the job names none), --set applied
};

// Reads a job file, expands `world:`, applies the --set overrides ("key=value" each).
Result<LoadedJob> LoadJobFile(const std::string& path, const std::vector<std::string>& sets);
// The same for a job given as text (a daemon request): `origin` names it in messages,
// relative paths resolve against `folder`.
Result<LoadedJob> LoadJobText(const std::string& text, const std::string& origin,
                              const std::string& folder, const std::vector<std::string>& sets);

// Resolves a path from a job file: absolute stays, relative is taken from `folder`.
std::string ResolvePath(const std::string& folder, const std::string& path);

// Section readers: fill the Options from a strict reader and validate them at the right line
// (the world's: sim/world_config.h).
void ReadStripeOptions(ConfigReader& r, vision::StripeOptions* options);

// `machine:` section: backend name, calibration file; the world comes from `world:`.
struct MachineSpec {
  hw::MachineConfig config;
  std::string calibration_path;  // resolved
};
void ReadMachine(ConfigReader& root, const std::string& folder, MachineSpec* spec);

// The keys every job file starts with: `job`, `description`, `world` and `world_changes`
// (already applied by LoadJobFile) and the `machine:` section.
void ReadJobHeader(ConfigReader& root, const LoadedJob& job, MachineSpec* machine);

// The machine config for a job: the backend from `spec` and, for the simulator, the job's
// world (world file, world_changes and --set applied), read strictly. Errors: a sim job
// without a world; bad world keys.
Status MachineConfigFor(const LoadedJob& job, const MachineSpec& spec, hw::MachineConfig* out);

}  // namespace insitu::job
