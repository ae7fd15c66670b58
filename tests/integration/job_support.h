// Running the shipped job files from the integration tests, as an operator would with
// `insitu run JOB --set ...`.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "insitu/hw/cell.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/job/job_file.h"
#include "insitu/job/runner.h"
#include "insitu/sim/world.h"

namespace insitu::testing {

// Re-registers the "sim" backend so the test can reach the world the last job brought up: the
// simulator's truth, to measure a job's results against.
inline std::shared_ptr<sim::SimWorld>& LastSimWorld() {
  static std::shared_ptr<sim::SimWorld> world;
  return world;
}
inline void KeepTheWorld() {
  hw::RegisterBackend("sim", [](const hw::MachineConfig& config) -> Result<hw::Machine> {
    INSITU_RETURN_IF_ERROR(config.world.Validate());
    LastSimWorld() = std::make_shared<sim::SimWorld>(config.world);
    return hw::CreateMachineOn(config, LastSimWorld());
  });
}

// `a` followed by `b`: a job's --set overrides built up from shared ones.
inline std::vector<std::string> With(std::vector<std::string> a,
                                     const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

inline std::string JobFile(const std::string& name) {
  return std::string(INSITU_SOURCE_DIR) + "/config/jobs/" + name;
}

// Loads config/jobs/<name> with the overrides and runs it into `out_dir`.
inline Result<job::Report> RunShippedJob(const std::string& name,
                                         const std::vector<std::string>& sets,
                                         const std::string& out_dir) {
  auto loaded = job::LoadJobFile(JobFile(name), sets);
  if (!loaded.ok()) return loaded.status();
  job::RunOptions options;
  options.out_dir = out_dir;
  return job::RunJob(*loaded, options);
}

// The calibrate job on a coarser height grid than the shipped one (5 mm in z, line offsets
// within +-20 mm), writing `calibration`: it keeps the tests short, and the lookup's cubic
// interpolation holds its own error far below the speckle noise for parts within that volume.
inline Result<job::Report> QuickCalibrate(const std::string& calibration,
                                          const std::string& out_dir,
                                          std::vector<std::string> sets = {}) {
  for (const char* s : {"height.z_step_mm=5", "height.x_start_mm=-20", "height.x_end_mm=20"}) {
    sets.emplace_back(s);
  }
  sets.push_back("output.calibration=" + calibration);
  return RunShippedJob("calibrate.yaml", sets, out_dir);
}

// What an operator runs on a new cell: calibrate (QuickCalibrate) into dir/machine.yaml, then
// field_calibration into dir/measured.yaml, both on `world`'s keys. Returns the field
// calibration's report (the measured calibration's path in `measured`), or the first failure.
inline Result<job::Report> CalibrateAndMeasureHead(const std::string& dir,
                                                   const std::vector<std::string>& world,
                                                   std::string* measured) {
  const std::string cal = dir + "/machine.yaml";
  *measured = dir + "/measured.yaml";
  auto calibrated = QuickCalibrate(cal, dir + "/calibrate", world);
  if (!calibrated.ok()) return calibrated.status();
  std::vector<std::string> sets = world;
  sets.push_back("machine.calibration=" + cal);
  sets.push_back("output.calibration=" + *measured);
  return RunShippedJob("field_calibration.yaml", sets, dir + "/field");
}

// Where the whole-cell diagnosis starts: the default cell calibrated (QuickCalibrate) into
// dir/machine.yaml and its diagnose_machine baseline recorded beside it
// (dir/diagnose_baseline.csv). Returns the calibration's path.
inline Result<std::string> CalibrateWithDiagnoseBaseline(const std::string& dir) {
  const std::string calibration = dir + "/machine.yaml";
  auto calibrated = QuickCalibrate(calibration, dir + "/calibrate");
  if (!calibrated.ok()) return calibrated.status();
  auto baseline = RunShippedJob(
      "diagnose_machine.yaml",
      {"machine.calibration=" + calibration, "diagnosis.record_baseline=true"}, dir + "/baseline");
  if (!baseline.ok()) return baseline.status();
  return calibration;
}

}  // namespace insitu::testing
