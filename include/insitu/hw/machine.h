// A machine = scan head + camera + stage + the clock they share, created by name.
// Only apps choose the backend; everything else works on these interfaces.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/camera.h"
#include "insitu/hw/operator.h"
#include "insitu/hw/scanner.h"
#include "insitu/hw/stage.h"
#include "insitu/sim/world_options.h"

namespace insitu::hw {

// Time as the devices see it: virtual on the simulator, the wall clock on a real machine.
class MachineClock {
 public:
  virtual ~MachineClock() = default;
  virtual double Now() const = 0;            // seconds
  virtual void SleepFor(double seconds) = 0;
};

struct Machine {
  std::unique_ptr<Scanner> scanner;
  std::unique_ptr<Camera> camera;   // the side camera that sees the pointer line
  std::unique_ptr<Camera> coaxial;  // looks through the scan head; null if the head has none
  std::unique_ptr<Stage> stage;
  std::unique_ptr<MachineClock> clock;
  std::unique_ptr<Operator> person;
};

// What a backend needs to come up. Each backend reads only its own part.
struct MachineConfig {
  std::string backend = "sim";
  sim::WorldOptions world;  // backend "sim": the simulated world
};

using BackendFactory = std::function<Result<Machine>(const MachineConfig&)>;

// Registers a backend under a name (done once per backend at start-up).
void RegisterBackend(const std::string& name, BackendFactory factory);
std::vector<std::string> BackendNames();

// Creates the machine of config.backend. Errors: not_found naming the known backends (a real
// backend that was not built is reported as such, never silently replaced by the simulator).
Result<Machine> CreateMachine(const MachineConfig& config);

}  // namespace insitu::hw
