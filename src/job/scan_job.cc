#include "job/scan_job.h"

#include <string>

namespace insitu::job {

namespace {

void ReadScanSection(ConfigReader& r, ScanOptions* s) {
  r.Read("x_start_mm", &s->x_start_mm);
  r.Read("x_end_mm", &s->x_end_mm);
  r.Read("line_spacing_mm", &s->line_spacing_mm);
  r.Read("y_start_mm", &s->y_start_mm);
  r.Read("y_end_mm", &s->y_end_mm);
  r.Read("focus_z_mm", &s->focus_z_mm);
  r.Read("speed_mm_per_s", &s->speed_mm_per_s);
  r.Read("settle_ms", &s->settle_ms);
}

}  // namespace

Status ReadScanJob(const LoadedJob& job, ScanJobSpec* spec, hw::MachineConfig* machine,
                   const std::function<void(ConfigReader&)>& extra) {
  ConfigReader r(job.root);
  ReadJobHeader(r, job, &spec->machine);
  ConfigReader& scan = r.Section("scan");
  ReadScanSection(scan, &spec->scan);
  ConfigReader& cam = r.Section("camera");
  cam.Read("exposure_ms", &spec->scan.exposure_ms);
  cam.Read("gain_db", &spec->scan.gain_db);
  cam.Read("binning", &spec->scan.binning);
  if (scan.ok() && cam.ok()) {
    const Status st = spec->scan.Validate();
    // The check names a key of either section; point at whichever holds it.
    const std::string first = st.message().substr(0, st.message().find(' '));
    if (cam.Has(first) || first == "exposure_ms" || first == "gain_db" || first == "binning") {
      cam.FailFromValidate(st);
    } else {
      scan.FailFromValidate(st);
    }
  }
  ReadStripeOptions(r.Section("extraction"), &spec->extraction);
  ConfigReader& rec = r.Section("reconstruction");
  const bool accuracy = job.kind == "accuracy";
  if (accuracy) spec->method = 2;  // method 2, with method 1 from the same centres
  rec.Read("method", &spec->method);
  if (rec.ok() && accuracy && spec->method != 2) {
    rec.Fail("method", "must be 2 in an accuracy job (it reports method 1 alongside)");
  }
  if (rec.ok() && spec->method != 1 && spec->method != 2) {
    rec.Fail("method", "is " + std::to_string(spec->method) +
                           ", expected 1 (camera + light plane) or 2 (plus height lookup)");
  }
  spec->scan.method = spec->method;
  ConfigReader& out = r.Section("output");
  out.Read("save_frames", &spec->save_frames);
  if (extra) extra(r);
  INSITU_RETURN_IF_ERROR(r.Finish());
  return MachineConfigFor(job, spec->machine, machine);
}


Result<ScanMachine> BringUp(const LoadedJob& job, const ScanJobSpec& spec,
                            const hw::MachineConfig& config) {
  auto calibration = calib::LoadCalibration(spec.machine.calibration_path);
  if (!calibration.ok()) return calibration.status().Prefixed(job.path + ": machine.calibration");
  INSITU_ASSIGN_OR_RETURN(hw::Machine machine, hw::CreateMachine(config));
  const hw::CameraInfo info = machine.camera->info();
  INSITU_RETURN_IF_ERROR(calib::CheckCameraMatches(calibration->camera, info.model, info.serial,
                                                   info.sensor_width_px, info.sensor_height_px)
                             .Prefixed(spec.machine.calibration_path));
  return ScanMachine{std::move(machine), std::move(*calibration)};
}

}  // namespace insitu::job
