#include "job/scan_job.h"

#include <string>

#include "job/cell.h"

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
  r.Read("streaming", &s->streaming);
  r.Read("queue_frames", &s->queue_frames);
  r.Read("region", &s->region);
  r.ReadArray("height_range_mm", s->height_range_mm.data(), 2);
  r.Read("min_stripe_fraction", &s->min_stripe_fraction);
  r.Read("background_frames", &s->background_frames);
}

}  // namespace

Status ReadScanJob(const LoadedJob& job, ScanJobSpec* spec, hw::MachineConfig* machine,
                   const std::function<void(ConfigReader&)>& extra) {
  ConfigReader r(job.root);
  ReadJobHeader(r, job, &spec->machine);
  ConfigReader& scan = r.Section("scan");
  ReadScanSection(scan, &spec->scan);
  ConfigReader& cam = r.Section("camera");
  // Auto exposure unless the job file sets an exposure (then it is the start if asked for).
  spec->scan.auto_exposure = !cam.Has("exposure_ms");
  cam.Read("exposure_ms", &spec->scan.exposure_ms);
  cam.Read("auto_exposure", &spec->scan.auto_exposure);
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


void ReportScanLight(const ScanStats& st, Report* report) {
  auto& m = report->metrics;
  m["lines"] = st.lines;
  m["valid_fraction"] =
      st.scan_lines_examined ? static_cast<double>(st.valid) / st.scan_lines_examined : 0.0;
  m["columns_valid"] = static_cast<double>(st.valid);
  m["columns_expected"] = static_cast<double>(st.expected_columns);
  m["columns_none"] = static_cast<double>(st.none);
  m["columns_saturated"] = static_cast<double>(st.saturated);
  m["columns_two_peaks"] = static_cast<double>(st.two_peaks);
  m["columns_too_wide"] = static_cast<double>(st.too_wide);
  m["columns_bad_shape"] = static_cast<double>(st.bad_shape);
  m["exposure_ms"] = st.exposure_ms;
  m["auto_exposure_shots"] = st.auto_exposure_shots;
  m["pointer_speed_mm_per_s"] = st.pointer_speed_mm_per_s;
  m["background_frames"] = st.background_frames;
  m["background_level"] = st.background_level;
  m["machine_time_s"] = st.machine_time_s;
  m["extract_time_ms_per_frame"] = st.lines ? st.extract_time_ms / st.lines : 0.0;
  // The camera as the scan ran it: its band of rows and the frames per second of machine time.
  m["camera_rows"] = st.region_rows;
  m["camera_frame_rate_hz"] = st.machine_time_s > 0 ? st.lines / st.machine_time_s : 0.0;
  m["max_queued_frames"] = st.max_queued_frames;
  // 1: the scan head's pulses exposed the lines (camera.head_trigger / lmc.trigger_port).
  m["camera_head_triggered"] = st.trigger == "head" ? 1.0 : 0.0;
  if (!st.region_note.empty()) report->warnings.push_back("camera region: " + st.region_note);
  if (!st.exposure_note.empty()) report->warnings.push_back(st.exposure_note);
  // A saturated column's centre is lost (the plateau hides the peak): it matters once it is
  // more than a stray speckle grain, 1 % of the lit columns.
  if (st.saturated > 0 && st.saturated * 100 > st.valid + st.saturated) {
    report->warnings.push_back(std::to_string(st.saturated) + " of " +
                               std::to_string(st.valid + st.saturated) +
                               " lit stripe columns saturated and were left out: lower "
                               "camera.exposure_ms or gain, or set camera.auto_exposure: true");
  }
  // Too dark: the lines cover columns that gave no stripe (a dark or steep surface, or
  // nothing there). Worth saying when most of them did.
  if (st.expected_columns > 0 && st.valid * 2 < st.expected_columns) {
    report->warnings.push_back(
        "the stripe was found in " + std::to_string(st.valid) + " of about " +
        std::to_string(st.expected_columns) +
        " columns the lines cover: too dark, too steep, or no part there (columns_none " +
        std::to_string(st.none) + ")");
  }
}

void ReadArtifact(ConfigReader& r, ScanJobSpec* spec) {
  if (r.Has("artifact")) {
    ConfigReader& a = r.Section("artifact");
    a.Require("kind");
    a.ReadEnum("kind", &spec->artifact, {"step_gauge", "insert"});
    if (spec->artifact == "step_gauge") {
      a.Read("heights_mm", &spec->gauge.heights_mm);
      a.Read("step_width_mm", &spec->gauge.step_width_mm);
      a.Read("length_mm", &spec->gauge.length_mm);
      double center[2] = {0, 0};
      a.ReadArray("center_mm", center, 2);
      spec->gauge.center_x_mm = center[0];
      spec->gauge.center_y_mm = center[1];
      a.Read("base_z_mm", &spec->gauge.base_z_mm);
      a.Read("edge_margin_mm", &spec->gauge.edge_margin_mm);
      a.Read("bin_mm", &spec->gauge.bin_mm);
      if (a.ok()) a.FailFromValidate(spec->gauge.Validate());
    } else if (spec->artifact == "insert") {
      inspect::InsertSpec& in = spec->insert;
      a.Read("thickness_mm", &in.thickness_mm);
      a.Read("edge_mm", &in.edge_mm);
      a.Read("hole_diameter_mm", &in.hole_diameter_mm);
      a.Read("tip_radius_mm", &in.tip_radius_mm);
      a.Read("base_z_mm", &in.base_z_mm);
      a.Read("gap_mm", &in.gap_mm);
      a.Read("inlier_mm", &in.inlier_mm);
      a.Read("corner_exclusion_mm", &in.corner_exclusion_mm);
      a.ReadArray("rake_fit_mm", in.rake_fit_mm.data(), 2);
      if (a.ok()) a.FailFromValidate(in.Validate());
    }
  }
}

Result<ScanMachine> BringUp(const LoadedJob& job, const ScanJobSpec& spec,
                            const hw::MachineConfig& config, const RunOptions& options,
                            std::initializer_list<hw::Role> more) {
  auto calibration = calib::LoadCalibration(spec.machine.calibration_path);
  if (!calibration.ok()) return calibration.status().Prefixed(job.path + ": machine.calibration");
  INSITU_ASSIGN_OR_RETURN(hw::Machine machine,
                          OpenCell(config, options, {hw::Role::kScanner, hw::Role::kCamera}, job));
  INSITU_RETURN_IF_ERROR(machine.Require(more, job.path + ": the " + job.kind + " job"));
  const hw::CameraInfo info = machine.camera->info();
  INSITU_RETURN_IF_ERROR(calib::CheckCameraMatches(calibration->camera, info.model, info.serial,
                                                   info.sensor_width_px, info.sensor_height_px)
                             .Prefixed(spec.machine.calibration_path));
  return ScanMachine{std::move(machine), std::move(*calibration)};
}

}  // namespace insitu::job
