// A machine: the devices of a cell, one per role, and the clock they share. Jobs work on these
// interfaces only; which device plays each role, and how a cell comes up, is hw/cell.h's.
#pragma once

#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/axis.h"
#include "insitu/hw/camera.h"
#include "insitu/hw/operator.h"
#include "insitu/hw/profiler.h"
#include "insitu/hw/scanner.h"
#include "insitu/hw/stage.h"

namespace insitu::hw {

// Time as the devices see it: virtual on the simulator, the wall clock on a real machine.
class MachineClock {
 public:
  virtual ~MachineClock() = default;
  virtual double Now() const = 0;  // seconds
  virtual void SleepFor(double seconds) = 0;
  // The machine stood idle `wall_seconds` of this computer's time while it computed (a scan
  // line processed before the next is started): on the wall clock that time has passed
  // already; a simulated clock advances by it, so machine times compare as on a real cell.
  virtual void Waited(double wall_seconds) { (void)wall_seconds; }
};

// The roles a cell's devices play; each is named by its key in a job's `machine:` section.
enum class Role { kScanner, kCamera, kCoaxial, kStage, kAxis, kProfiler, kOperator };
inline constexpr Role kRoles[] = {Role::kScanner, Role::kCamera, Role::kCoaxial, Role::kStage,
                                  Role::kAxis,    Role::kProfiler, Role::kOperator};
// "scanner", "camera", "coaxial", "stage", "axis", "profiler", "operator".
const char* RoleKey(Role role);
// "scan head", "side camera", "coaxial camera", "Z stage", "axis", "line profiler", "operator".
const char* RoleName(Role role);
// failed_precondition: `who` needs a device for `role` and the cell (`real` or simulated) has
// none. The one wording of the refusal, at run and at bring-up.
Status MissingRole(Role role, const std::string& who, bool real);

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
  // True when any device is real hardware: the cell runs on the wall clock, and a role it does
  // not name has no device.
  bool real = false;
  // For every job's report: simulated devices on a real cell (a dry run), and the like.
  std::vector<std::string> warnings;

  bool Has(Role role) const;
  // Errors: failed_precondition naming the first role in `roles` the cell has no device for,
  // and `who` (e.g. "a calibrate job") that needs it. Jobs call it before anything moves.
  Status Require(std::initializer_list<Role> roles, const std::string& who) const;
};

}  // namespace insitu::hw
