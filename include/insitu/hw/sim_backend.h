// The simulator behind the hw interfaces. Apps reach it through CreateMachine("sim"); tests
// that need the simulator's truth build the machine around a SimWorld they keep.
#pragma once

#include <memory>

#include "insitu/hw/machine.h"
#include "insitu/sim/world.h"

namespace insitu::hw {

// A machine whose devices all drive `world`.
Machine MakeSimMachine(std::shared_ptr<sim::SimWorld> world);

// The cell `config` names, its simulated devices on `world` (config.world is not used): what
// CreateMachine does, for tests that keep the world to measure against its truth.
struct MachineConfig;
Result<Machine> CreateMachineOn(const MachineConfig& config, std::shared_ptr<sim::SimWorld> world);

}  // namespace insitu::hw
