#include "insitu/hw/machine.h"

#include <map>
#include <mutex>

#include "insitu/hw/sim_backend.h"

namespace insitu::hw {
namespace {

std::mutex g_mutex;

std::map<std::string, BackendFactory>& Registry() {
  static std::map<std::string, BackendFactory> registry = [] {
    std::map<std::string, BackendFactory> r;
    r["sim"] = [](const MachineConfig& config) -> Result<Machine> {
      INSITU_RETURN_IF_ERROR(config.world.Validate().Prefixed("world"));
      return MakeSimMachine(std::make_shared<sim::SimWorld>(config.world));
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
