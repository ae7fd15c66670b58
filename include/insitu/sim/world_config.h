// The `world:` document a job names (config/worlds/): read strictly into WorldOptions, each
// section validated at its line. The simulator's own configuration, read by whoever brings a
// simulated cell up.
#pragma once

#include "insitu/core/config.h"
#include "insitu/sim/world_options.h"

namespace insitu::sim {

void ReadWorld(ConfigReader& r, WorldOptions* world);

}  // namespace insitu::sim
