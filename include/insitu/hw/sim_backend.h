// The simulator behind the hw interfaces. Apps reach it through CreateMachine("sim"); tests
// that need the simulator's truth build the machine around a SimWorld they keep.
#pragma once

#include <memory>

#include "insitu/hw/machine.h"
#include "insitu/sim/world.h"

namespace insitu::hw {

// A machine whose devices all drive `world`.
Machine MakeSimMachine(std::shared_ptr<sim::SimWorld> world);

}  // namespace insitu::hw
