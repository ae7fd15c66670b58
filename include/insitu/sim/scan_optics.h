// The simulator's scan optics are the project's head model (optics/scan_head.h): the truth
// the simulated head traces, under the names the simulator has always used.
#pragma once

#include "insitu/optics/scan_head.h"

namespace insitu::sim {

using MirrorAngles = optics::MirrorAngles;
using ChiefRay = optics::ChiefRay;
using ScanOptics = optics::ScanOptics;

}  // namespace insitu::sim
