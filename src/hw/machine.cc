#include "insitu/hw/machine.h"

#include <chrono>
#include <map>
#include <mutex>
#include <thread>

#include "insitu/hw/lmc_cor.h"
#include "insitu/hw/lmc_sim_board.h"
#include "insitu/hw/sim_backend.h"

namespace insitu::hw {
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

}  // namespace

Status ReplaceDevices(const MachineConfig& config, std::shared_ptr<sim::SimWorld> world,
                      Machine* m) {
  bool real = false;
  if (config.scanner == "lmc") {
    const LmcDeviceConfig& l = config.lmc;
    INSITU_RETURN_IF_ERROR(l.board.Validate().Prefixed("lmc.board"));
    std::unique_ptr<lmc::Transport> transport;
    if (l.transport == "sim_board") {
      if (world == nullptr) {
        return InvalidArgument("lmc.transport sim_board needs the sim backend (a simulated head)");
      }
      transport = std::make_unique<lmc::SimBoard>(world, l.board);
    } else if (l.transport == "usb") {
      INSITU_ASSIGN_OR_RETURN(transport, lmc::OpenUsb(l.usb));
      real = true;
    } else {
      return InvalidArgument("lmc.transport '" + l.transport + "' is not usb or sim_board");
    }
    if (!l.correction_file.empty()) {
      INSITU_ASSIGN_OR_RETURN(const lmc::CorFile cor, lmc::ReadCor(l.correction_file));
      INSITU_RETURN_IF_ERROR(lmc::UploadCorrection(*transport, lmc::ToBoard(cor))
                                 .Prefixed("uploading " + l.correction_file));
    }
    m->scanner = lmc::MakeScanner(std::move(transport), l.board);
  } else if (!config.scanner.empty() && config.scanner != config.backend) {
    return NotFound("scanner backend '" + config.scanner + "' does not exist (known: lmc)");
  }
  if (config.camera == "aravis") {
    aravis::CameraOptions options = config.aravis.camera;
    if (!config.aravis.simulate_on.empty()) {
      if (world == nullptr) {
        return InvalidArgument("aravis.simulate_on needs the sim backend (a simulated camera)");
      }
      INSITU_ASSIGN_OR_RETURN(std::shared_ptr<aravis::SimulatedGigECamera> served,
                              aravis::SimulatedGigECamera::Start(world, config.aravis.simulate_on,
                                                                 world->options().camera.serial));
      served->SetLostPacketRatio(config.aravis.lost_packet_ratio);
      m->peers.push_back(served);
      options.device = config.aravis.simulate_on;
      // The served camera renders each frame on this computer after the trigger: on a loaded
      // machine that takes seconds, which a real camera's timeout does not allow for.
      options.frame_timeout_ms += kSimulatedRenderAllowanceMs;
      options.roi_width = world->options().camera.width_px;
      options.roi_height = world->options().camera.height_px;
    } else {
      real = true;
    }
    INSITU_ASSIGN_OR_RETURN(m->camera, aravis::OpenCamera(options));
  } else if (!config.camera.empty() && config.camera != config.backend) {
    return NotFound("camera backend '" + config.camera + "' does not exist (known: aravis)");
  }
  if (config.profiler == "aravis") {
    aravis::ProfilerOptions options = config.aravis_profiler.profiler;
    if (!config.aravis_profiler.simulate_on.empty()) {
      if (world == nullptr || m->profiler == nullptr) {
        return InvalidArgument(
            "aravis_profiler.simulate_on needs the sim backend with a profiler (world.profiler)");
      }
      std::shared_ptr<Profiler> source = std::move(m->profiler);
      INSITU_ASSIGN_OR_RETURN(
          std::shared_ptr<aravis::SimulatedGigEProfiler> served,
          aravis::SimulatedGigEProfiler::Start(source, config.aravis_profiler.simulate_on,
                                               world->options().profiler.serial));
      served->SetLostPacketRatio(config.aravis_profiler.lost_packet_ratio);
      m->peers.push_back(served);
      options.device = config.aravis_profiler.simulate_on;
      options.frame_timeout_ms += kSimulatedRenderAllowanceMs;
    } else {
      real = true;
    }
    INSITU_ASSIGN_OR_RETURN(m->profiler, aravis::OpenProfiler(options));
  } else if (!config.profiler.empty() && config.profiler != config.backend) {
    return NotFound("profiler backend '" + config.profiler + "' does not exist (known: aravis)");
  }
  // Real devices run on the wall clock: a settle time must really pass.
  if (real) m->clock = std::make_unique<WallClock>();
  return Status::Ok();
}

namespace {

std::map<std::string, BackendFactory>& Registry() {
  static std::map<std::string, BackendFactory> registry = [] {
    std::map<std::string, BackendFactory> r;
    r["sim"] = [](const MachineConfig& config) -> Result<Machine> {
      INSITU_RETURN_IF_ERROR(config.world.Validate().Prefixed("world"));
      auto world = std::make_shared<sim::SimWorld>(config.world);
      Machine m = MakeSimMachine(world);
      INSITU_RETURN_IF_ERROR(ReplaceDevices(config, world, &m));
      return m;
    };
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
