// Which device plays each role (hw/cell.h): the rules alone, without opening anything, so
// job files are checked (and fuzzed) without the backends.
#include "insitu/hw/cell.h"

namespace insitu::hw {
// A device the simulator provides: its own, or served through a real protocol.
bool IsSimulatedDevice(const MachineConfig& c, Role role) {
  const std::string d = DeviceFor(c, role);
  if (d == "sim") return true;
  switch (role) {
    case Role::kScanner: return d == "lmc" && c.lmc.transport == "sim_board";
    case Role::kCamera: return d == "aravis" && !c.aravis.simulate_on.empty();
    case Role::kProfiler: return d == "aravis" && !c.aravis_profiler.simulate_on.empty();
    default: return false;
  }
}

std::string& DeviceField(MachineConfig& c, Role role) {
  switch (role) {
    case Role::kScanner: return c.scanner;
    case Role::kCamera: return c.camera;
    case Role::kCoaxial: return c.coaxial;
    case Role::kStage: return c.stage;
    case Role::kAxis: return c.axis;
    case Role::kProfiler: return c.profiler;
    case Role::kOperator: return c.person;
  }
  return c.scanner;
}

const std::string& DeviceField(const MachineConfig& c, Role role) {
  return DeviceField(const_cast<MachineConfig&>(c), role);
}

std::string DeviceFor(const MachineConfig& c, Role role) {
  const std::string& named = DeviceField(c, role);
  if (!named.empty()) return named;
  return IsRealCell(c) ? "none" : "sim";
}

bool IsRealDevice(const MachineConfig& c, Role role) {
  const std::string& d = DeviceField(c, role);
  switch (role) {
    case Role::kScanner: return d == "lmc" && c.lmc.transport == "usb";
    case Role::kCamera: return d == "aravis" && c.aravis.simulate_on.empty();
    case Role::kProfiler: return d == "aravis" && c.aravis_profiler.simulate_on.empty();
    case Role::kStage: return d == "grbl";
    default: return false;
  }
}

bool IsRealCell(const MachineConfig& c) {
  for (Role r : kRoles) {
    if (IsRealDevice(c, r)) return true;
  }
  return false;
}

bool NeedsSimulator(const MachineConfig& c) {
  for (Role r : kRoles) {
    if (IsSimulatedDevice(c, r)) return true;
  }
  // A person rehearsing on a simulated cell acts through the simulator's hands.
  return !IsRealCell(c);
}

}  // namespace insitu::hw
