// A machine = scan head + camera + stage (+ a profiler on its axis) + the clock they share,
// created by name.
// Only apps choose the backend; everything else works on these interfaces.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/aravis.h"
#include "insitu/hw/aravis_profiler.h"
#include "insitu/hw/axis.h"
#include "insitu/hw/camera.h"
#include "insitu/hw/lmc.h"
#include "insitu/hw/operator.h"
#include "insitu/hw/profiler.h"
#include "insitu/hw/scanner.h"
#include "insitu/hw/stage.h"
#include "insitu/sim/world_options.h"

namespace insitu::sim {
class SimWorld;
}  // namespace insitu::sim

namespace insitu::hw {

// Time as the devices see it: virtual on the simulator, the wall clock on a real machine.
class MachineClock {
 public:
  virtual ~MachineClock() = default;
  virtual double Now() const = 0;  // seconds
  virtual void SleepFor(double seconds) = 0;
};

struct Machine {
  // What the backend serves for its own devices to talk to (a simulated GigE camera, a board
  // emulator's world): destroyed last, after the devices.
  std::vector<std::shared_ptr<void>> peers;
  std::unique_ptr<Scanner> scanner;
  std::unique_ptr<Camera> camera;   // the side camera that sees the pointer line
  std::unique_ptr<Camera> coaxial;  // looks through the scan head; null if the head has none
  std::unique_ptr<Stage> stage;
  std::unique_ptr<MachineClock> clock;
  std::unique_ptr<Operator> person;
  std::unique_ptr<Axis> axis;          // carries the profiler; null if the cell has none
  std::unique_ptr<Profiler> profiler;  // a line profiler on the axis; null if none
};

// A GigE Vision camera through Aravis in place of the backend's camera (camera: aravis).
struct AravisDeviceConfig {
  aravis::CameraOptions camera;
  // Backend sim only: serve the world's camera as a GigE Vision camera on this local address
  // (127.0.0.1) and open that one, so frames travel over real GVCP/GVSP. Its frame timeout
  // gets 20 s more: the simulator renders each frame after the trigger. Empty: a real camera.
  std::string simulate_on;
  double lost_packet_ratio = 0.0;  // of the served camera's packets (a lossy link)
};

// A GenICam 3D line profiler through Aravis in place of the backend's (profiler: aravis).
struct AravisProfilerConfig {
  aravis::ProfilerOptions profiler;
  // Backend sim only: serve the world's profiler as a GigE Vision 3D camera on this local
  // address and open that one, so profiles travel over real GVCP/GVSP. Empty: a real sensor.
  std::string simulate_on;
  double lost_packet_ratio = 0.0;
};

// An LMC galvo board in place of the backend's scan head (scanner: lmc).
struct LmcDeviceConfig {
  std::string transport = "usb";  // usb, or sim_board: the board emulator on the simulated head
  lmc::UsbSelector usb;
  lmc::BoardOptions board;
  std::string correction_file;  // a .cor file uploaded to the board when it opens
};

// What a backend needs to come up. Each backend reads only its own part.
struct MachineConfig {
  std::string backend = "sim";
  // Devices by name in place of the backend's own: camera "aravis", scanner "lmc". Empty: the
  // backend's. A named device that cannot be opened is an error, never replaced by another.
  std::string camera;
  std::string scanner;
  std::string profiler;  // "aravis", or empty: the backend's
  sim::WorldOptions world;  // backend "sim": the simulated world
  AravisDeviceConfig aravis;
  AravisProfilerConfig aravis_profiler;
  LmcDeviceConfig lmc;
};

using BackendFactory = std::function<Result<Machine>(const MachineConfig&)>;

// Registers a backend under a name (done once per backend at start-up).
void RegisterBackend(const std::string& name, BackendFactory factory);
std::vector<std::string> BackendNames();

// Puts the devices config.camera and config.scanner name in place of the backend's own
// (backends call it; `world` is the simulated world when the backend has one, for the board
// emulator and the served GigE camera). Errors name the device that cannot be opened.
Status ReplaceDevices(const MachineConfig& config, std::shared_ptr<sim::SimWorld> world,
                      Machine* machine);

// Creates the machine of config.backend. Errors: not_found naming the known backends (a real
// backend that was not built is reported as such, never silently replaced by the simulator).
Result<Machine> CreateMachine(const MachineConfig& config);

}  // namespace insitu::hw
