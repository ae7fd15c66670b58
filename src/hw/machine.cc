#include <algorithm>
#include <chrono>
#include <map>
#include <mutex>
#include <thread>

#include "hw/aravis/camera.h"
#include "hw/aravis/profiler.h"
#include "hw/grbl/stage.h"
#include "hw/lmc/lmc.h"
#include "hw/lmc/sim_board.h"
#include "insitu/hw/cell.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/hw/sim_backend.h"

namespace insitu::hw {

const char* RoleKey(Role role) {
  switch (role) {
    case Role::kScanner: return "scanner";
    case Role::kCamera: return "camera";
    case Role::kCoaxial: return "coaxial";
    case Role::kStage: return "stage";
    case Role::kAxis: return "axis";
    case Role::kProfiler: return "profiler";
    case Role::kOperator: return "operator";
  }
  return "?";
}

const char* RoleName(Role role) {
  switch (role) {
    case Role::kScanner: return "scan head";
    case Role::kCamera: return "side camera";
    case Role::kCoaxial: return "coaxial camera";
    case Role::kStage: return "Z stage";
    case Role::kAxis: return "axis";
    case Role::kProfiler: return "line profiler";
    case Role::kOperator: return "operator";
  }
  return "?";
}

bool Machine::Has(Role role) const {
  switch (role) {
    case Role::kScanner: return scanner != nullptr;
    case Role::kCamera: return camera != nullptr;
    case Role::kCoaxial: return coaxial != nullptr;
    case Role::kStage: return stage != nullptr;
    case Role::kAxis: return axis != nullptr;
    case Role::kProfiler: return profiler != nullptr;
    case Role::kOperator: return person != nullptr;
  }
  return false;
}

Status Machine::Require(std::initializer_list<Role> roles, const std::string& who) const {
  for (Role r : roles) {
    if (Has(r)) continue;
    return MissingRole(r, who, real);
  }
  return Status::Ok();
}

Status MissingRole(Role role, const std::string& who, bool real) {
  return FailedPrecondition(who + " needs a " + RoleName(role) + ", and the cell has none " +
                            "(machine." + RoleKey(role) + " names no device" +
                            (real ? " on this real cell" : "") + ")");
}

namespace {

std::mutex g_mutex;

constexpr double kSimulatedRenderAllowanceMs = 20000.0;

class WallClock : public MachineClock {
 public:
  WallClock() : start_(std::chrono::steady_clock::now()) {}
  double Now() const override {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  void SleepFor(double seconds) override {
    if (seconds > 0) std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

Result<std::unique_ptr<Scanner>> OpenLmc(const LmcDeviceConfig& l,
                                         std::shared_ptr<sim::SimWorld> world) {
  INSITU_RETURN_IF_ERROR(l.board.Validate().Prefixed("lmc.board"));
  std::unique_ptr<lmc::Transport> transport;
  if (l.transport == "sim_board") {
    transport = std::make_unique<lmc::SimBoard>(world, l.board);
  } else if (l.transport == "usb") {
    INSITU_ASSIGN_OR_RETURN(transport, lmc::OpenUsb(l.usb));
  } else {
    return InvalidArgument("lmc.transport '" + l.transport + "' is not usb or sim_board");
  }
  if (!l.capture_file.empty()) {
    INSITU_ASSIGN_OR_RETURN(transport, lmc::Capturing(std::move(transport), l.capture_file));
  }
  lmc::BoardCorrection table;  // none: a blank one, the board corrects nothing
  if (!l.correction_file.empty()) {
    INSITU_ASSIGN_OR_RETURN(const lmc::CorFile cor, lmc::ReadCor(l.correction_file));
    table = lmc::ToBoard(cor);
  }
  auto opened = lmc::OpenScanner(std::move(transport), l.board, std::move(table));
  if (!opened.ok()) {
    return opened.status().Prefixed(l.correction_file.empty()
                                        ? "starting the board"
                                        : "starting the board with " + l.correction_file);
  }
  return std::move(*opened);
}

Result<std::unique_ptr<Camera>> OpenAravisCamera(const AravisDeviceConfig& a,
                                                 std::shared_ptr<sim::SimWorld> world,
                                                 Machine* m) {
  aravis::CameraOptions options = a.camera;
  if (!a.simulate_on.empty()) {
    if (options.trigger != "software") {
      // Aravis's fake camera sends frames on software triggers only.
      return InvalidArgument(
          "aravis.trigger: the GigE camera served by the simulator takes software trigger only "
          "(camera: sim with the world's camera.head_trigger models a camera on the head's "
          "trigger output)");
    }
    INSITU_ASSIGN_OR_RETURN(std::shared_ptr<aravis::SimulatedGigECamera> served,
                            aravis::SimulatedGigECamera::Start(world, a.simulate_on,
                                                               world->options().camera.serial));
    served->SetLostPacketRatio(a.lost_packet_ratio);
    m->peers.push_back(served);
    options.device = a.simulate_on;
    // The served camera renders each frame on this computer after the trigger: on a loaded
    // machine that takes seconds, which a real camera's timeout does not allow for.
    options.frame_timeout_ms += kSimulatedRenderAllowanceMs;
    options.roi_width = world->options().camera.width_px;
    options.roi_height = world->options().camera.height_px;
  }
  return aravis::OpenCamera(options);
}

Result<std::unique_ptr<Profiler>> OpenAravisProfiler(const AravisProfilerConfig& a,
                                                     std::unique_ptr<Profiler> simulated,
                                                     std::shared_ptr<sim::SimWorld> world,
                                                     Machine* m) {
  aravis::ProfilerOptions options = a.profiler;
  if (!a.simulate_on.empty()) {
    if (simulated == nullptr) {
      return InvalidArgument(
          "aravis_profiler.simulate_on needs a simulated profiler (world.profiler.present)");
    }
    std::shared_ptr<Profiler> source = std::move(simulated);
    INSITU_ASSIGN_OR_RETURN(std::shared_ptr<aravis::SimulatedGigEProfiler> served,
                            aravis::SimulatedGigEProfiler::Start(
                                source, a.simulate_on, world->options().profiler.serial));
    served->SetLostPacketRatio(a.lost_packet_ratio);
    m->peers.push_back(served);
    options.device = a.simulate_on;
    options.frame_timeout_ms += kSimulatedRenderAllowanceMs;
  }
  return aravis::OpenProfiler(options);
}

// A simulated device the world does not have (a coaxial camera on a head without one).
Status Absent(Role role, const char* world_key) {
  return FailedPrecondition(std::string("machine.") + RoleKey(role) + ": sim, but the world has no " +
                            RoleName(role) + " (world." + world_key + ".present is false)");
}

}  // namespace

Result<Machine> CreateMachineOn(const MachineConfig& config,
                                std::shared_ptr<sim::SimWorld> simulated) {
  for (Role r : kRoles) {
    const std::string& d = DeviceField(config, r);
    static const std::map<Role, std::vector<std::string>> kKnown = {
        {Role::kScanner, {"sim", "lmc", "none"}},    {Role::kCamera, {"sim", "aravis", "none"}},
        {Role::kCoaxial, {"sim", "none"}},           {Role::kStage, {"sim", "grbl", "none"}},
        {Role::kAxis, {"sim", "none"}},              {Role::kProfiler, {"sim", "aravis", "none"}},
        {Role::kOperator, {"sim", "person", "none"}}};
    const std::vector<std::string>& known = kKnown.at(r);
    if (d.empty() || std::find(known.begin(), known.end(), d) != known.end()) continue;
    std::string list;
    for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
    return NotFound(std::string("machine.") + RoleKey(r) + ": no device '" + d + "' (known: " +
                    list + ")");
  }
  Machine m;
  m.real = IsRealCell(config);
  std::shared_ptr<sim::SimWorld> world;
  Machine sim;  // the simulator's devices, moved into the roles that are simulated
  if (NeedsSimulator(config)) {
    if (simulated == nullptr) {
      INSITU_RETURN_IF_ERROR(config.world.Validate().Prefixed("world"));
      simulated = std::make_shared<sim::SimWorld>(config.world);
    }
    world = simulated;
    sim = MakeSimMachine(world);
    m.peers = std::move(sim.peers);
  }
  const auto role_error = [](Role r, const Status& s) {
    return s.Prefixed(std::string("machine.") + RoleKey(r));
  };

  const std::string scanner = DeviceFor(config, Role::kScanner);
  if (scanner == "sim") {
    m.scanner = std::move(sim.scanner);
  } else if (scanner == "lmc") {
    auto opened = OpenLmc(config.lmc, world);
    if (!opened.ok()) return role_error(Role::kScanner, opened.status());
    m.scanner = std::move(*opened);
    if (config.lmc.correction_file.empty()) {
      m.warnings.push_back(
          "lmc.correction names no table: the board was given a blank one and corrects "
          "nothing (a field.cor made here assumes so)");
    } else if (config.lmc.transport == "sim_board" && world &&
               world->options().scan_head.own_correction) {
      m.warnings.push_back(
          "the simulated head corrects itself (world.scan_head.own_correction: true) and the "
          "board applies " +
          config.lmc.correction_file +
          " on top: the field is corrected twice (set own_correction: false for a head "
          "driven linearly, as behind a real LMC board)");
    }
  }
  const std::string camera = DeviceFor(config, Role::kCamera);
  if (camera == "sim") {
    m.camera = std::move(sim.camera);
  } else if (camera == "aravis") {
    auto opened = OpenAravisCamera(config.aravis, world, &m);
    if (!opened.ok()) return role_error(Role::kCamera, opened.status());
    m.camera = std::move(*opened);
  }
  if (DeviceFor(config, Role::kCoaxial) == "sim") {
    if (sim.coaxial == nullptr && !config.coaxial.empty()) {
      return Absent(Role::kCoaxial, "scan_head.coaxial");
    }
    m.coaxial = std::move(sim.coaxial);
  }
  const std::string stage = DeviceFor(config, Role::kStage);
  if (stage == "sim") {
    m.stage = std::move(sim.stage);
  } else if (stage == "grbl") {
    auto opened = grbl::OpenStage(config.grbl);
    if (!opened.ok()) return role_error(Role::kStage, opened.status());
    m.stage = std::move(*opened);
  }
  if (DeviceFor(config, Role::kAxis) == "sim") {
    if (sim.axis == nullptr && !config.axis.empty()) return Absent(Role::kAxis, "gantry");
    m.axis = std::move(sim.axis);
  }
  const std::string profiler = DeviceFor(config, Role::kProfiler);
  if (profiler == "sim") {
    if (sim.profiler == nullptr && !config.profiler.empty()) {
      return Absent(Role::kProfiler, "profiler");
    }
    m.profiler = std::move(sim.profiler);
  } else if (profiler == "aravis") {
    auto opened = OpenAravisProfiler(config.aravis_profiler, std::move(sim.profiler), world, &m);
    if (!opened.ok()) return role_error(Role::kProfiler, opened.status());
    m.profiler = std::move(*opened);
  }
  const std::string person = DeviceFor(config, Role::kOperator);
  if (person == "sim") {
    m.person = std::move(sim.person);
  } else if (person == "person") {
    if (!config.ask_person) {
      return FailedPrecondition(
          "machine.operator: person, but nothing here can ask one (run the job from a terminal "
          "with insitu run, or through insitud, whose clients answer its prompt events)");
    }
    // On a simulated cell the person is asked and the simulator's hands then do it.
    m.person = MakePersonOperator(config.ask_person, std::move(sim.person));
  }
  // Real devices run on the wall clock: a settle time must really pass.
  if (m.real) {
    m.clock = std::make_unique<WallClock>();
  } else {
    m.clock = std::move(sim.clock);
  }
  if (m.real) {
    for (Role r : kRoles) {
      if (!IsSimulatedDevice(config, r) || !m.Has(r)) continue;
      m.warnings.push_back(std::string("dry run: the ") + RoleName(r) + " is simulated (machine." +
                           RoleKey(r) + ": " + DeviceFor(config, r) +
                           ") on a cell with real devices; what it " +
                           (r == Role::kOperator ? "does" : "moves or measures") + " is not real");
    }
  }
  return m;
}

namespace {

std::map<std::string, BackendFactory>& Registry() {
  static std::map<std::string, BackendFactory> registry = [] {
    std::map<std::string, BackendFactory> r;
    r["sim"] = [](const MachineConfig& config) { return CreateMachineOn(config, nullptr); };
    return r;
  }();
  return registry;
}

}  // namespace

void RegisterBackend(const std::string& name, BackendFactory factory) {
  std::lock_guard<std::mutex> lock(g_mutex);
  Registry()[name] = std::move(factory);
}

std::vector<std::string> BackendNames() {
  std::lock_guard<std::mutex> lock(g_mutex);
  std::vector<std::string> names;
  for (const auto& [name, factory] : Registry()) names.push_back(name);
  return names;
}

Result<Machine> CreateMachine(const MachineConfig& config) {
  BackendFactory factory;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    auto it = Registry().find(config.backend);
    if (it != Registry().end()) factory = it->second;
  }
  if (!factory) {
    std::string known;
    for (const std::string& n : BackendNames()) known += (known.empty() ? "" : ", ") + n;
    return NotFound("machine backend '" + config.backend + "' is not available in this build " +
                    "(available: " + known + ")");
  }
  return factory(config);
}

}  // namespace insitu::hw
