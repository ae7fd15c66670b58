// Which device plays each role of a cell, and bringing the cell up.
//
// A job's `machine:` section names a device for each role (scanner, camera, coaxial, stage,
// axis, profiler, operator). A cell is real as soon as one role names real hardware (an LMC
// board over USB, a GigE camera or profiler, a serial stage): then a role it does not name has
// no device, and a simulated device must be named (`sim`) and is reported as a dry run. On a
// simulated cell every role not named is the simulator's.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/aravis_options.h"
#include "insitu/hw/grbl_options.h"
#include "insitu/hw/lmc_options.h"
#include "insitu/hw/machine.h"
#include "insitu/sim/world_options.h"

namespace insitu::hw {

// A GigE Vision camera through Aravis (camera: aravis).
struct AravisDeviceConfig {
  aravis::CameraOptions camera;
  // Serve the world's camera as a GigE Vision camera on this local address (127.0.0.1) and
  // open that one, so frames travel over real GVCP/GVSP. Its frame timeout gets 20 s more: the
  // simulator renders each frame after the trigger. Empty: a real camera.
  std::string simulate_on;
  double lost_packet_ratio = 0.0;  // of the served camera's packets (a lossy link)
};

// A GenICam 3D line profiler through Aravis (profiler: aravis).
struct AravisProfilerConfig {
  aravis::ProfilerOptions profiler;
  // Serve the world's profiler as a GigE Vision 3D camera on this local address and open that
  // one, so profiles travel over real GVCP/GVSP. Empty: a real sensor.
  std::string simulate_on;
  double lost_packet_ratio = 0.0;
};

// An LMC galvo board (scanner: lmc).
struct LmcDeviceConfig {
  std::string transport = "usb";  // usb, or sim_board: the board emulator on the simulated head
  lmc::UsbSelector usb;
  lmc::BoardOptions board;
  std::string correction_file;  // a .cor file uploaded to the board when it opens
  // A USB capture of everything sent to the board and read back (lmc.capture; empty: none):
  // pcapng, or usbmon text for a .txt or .mon name (insitu/hw/lmc_capture.h).
  std::string capture_file;
};

// How the cell reaches the person at the machine (operator: person): shows `request` and
// returns when they have done it. Errors: cancelled when they refuse or the job is cancelled.
// The front end supplies it: a console prompt (insitu run), a prompt event answered by `ack`
// (insitud).
using AskPerson = std::function<Status(const std::string& request)>;

// What a cell needs to come up. Each device reads only its own part.
struct MachineConfig {
  std::string backend = "sim";
  // The device of each role: "sim", "none", or a real one (scanner lmc; camera and profiler
  // aravis; stage grbl; operator person). Empty: the simulator's on a simulated cell, none on a
  // real one. A named device that cannot be opened is an error, never replaced by another.
  std::string scanner, camera, coaxial, stage, axis, profiler, person;
  sim::WorldOptions world;  // the simulated world, when any role is simulated
  AravisDeviceConfig aravis;
  AravisProfilerConfig aravis_profiler;
  LmcDeviceConfig lmc;
  grbl::StageOptions grbl;
  AskPerson ask_person;  // operator: person
};

// The config's field for a role's device (scanner, camera, ..., person).
std::string& DeviceField(MachineConfig& config, Role role);
const std::string& DeviceField(const MachineConfig& config, Role role);
// The device a role resolves to: what the config names, else "sim" on a simulated cell and
// "none" on a real one.
std::string DeviceFor(const MachineConfig& config, Role role);
// True when the role names real hardware (opened on a bus or a port of this computer).
bool IsRealDevice(const MachineConfig& config, Role role);
// True when the role's device comes from the simulator: its own, or served through a real
// protocol (an LMC board emulator, a GigE camera or profiler served on a local address).
bool IsSimulatedDevice(const MachineConfig& config, Role role);
// True when any role names real hardware.
bool IsRealCell(const MachineConfig& config);
// True when some device comes from the simulator (so the job must name a world).
bool NeedsSimulator(const MachineConfig& config);

using BackendFactory = std::function<Result<Machine>(const MachineConfig&)>;

// Registers a backend under a name (done once per backend at start-up).
void RegisterBackend(const std::string& name, BackendFactory factory);
std::vector<std::string> BackendNames();

// Brings up the cell: each role's device, opened. Errors name the role and the device that
// cannot be opened; a backend this build lacks is not_found naming the known ones (never
// silently replaced by the simulator).
Result<Machine> CreateMachine(const MachineConfig& config);

}  // namespace insitu::hw
