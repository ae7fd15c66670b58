#include "insitu/job/runner.h"

#include <chrono>
#include <cmath>
#include <filesystem>

#include "insitu/calib/calibration.h"
#include "insitu/core/log.h"
#include "insitu/geometry/cloud.h"
#include "insitu/job/plot.h"
#include "insitu/job/scan.h"
#include "insitu/job/step_gauge.h"
#include "job/calibrate.h"

namespace insitu::job {
namespace {

struct ScanJobSpec {
  MachineSpec machine;
  ScanOptions scan;
  vision::StripeOptions extraction;
  int method = 1;
  bool has_artifact = false;
  StepGaugeSpec gauge;
  bool save_frames = false;
};

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

Status ReadScanJob(const LoadedJob& job, ScanJobSpec* spec, hw::MachineConfig* machine) {
  ConfigReader r(job.root);
  std::string kind;
  r.Read("job", &kind);
  r.Read("description", &kind);
  r.Skip("world");
  ReadMachine(r, job.folder, &spec->machine);
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
  rec.Read("method", &spec->method);
  if (rec.ok() && spec->method != 1) {
    rec.Fail("method", "is " + std::to_string(spec->method) +
                           "; this build reconstructs with method 1 (camera + light plane)");
  }
  ConfigReader& out = r.Section("output");
  out.Read("save_frames", &spec->save_frames);
  if (r.Has("artifact")) {
    spec->has_artifact = true;
    ConfigReader& a = r.Section("artifact");
    std::string akind;
    a.Require("kind");
    a.ReadEnum("kind", &akind, {"step_gauge"});
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
  }
  INSITU_RETURN_IF_ERROR(r.Finish());
  *machine = spec->machine.config;
  if (machine->backend == "sim") {
    if (!job.world.IsDefined()) {
      return InvalidArgument(job.path + ": machine.backend is sim but the job names no world");
    }
    ConfigReader w(job.world);
    ReadWorld(w, &machine->world);
    INSITU_RETURN_IF_ERROR(w.Finish());
  }
  return Status::Ok();
}

std::string FormatMm(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

Result<Report> RunScanJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ScanJobSpec spec;
  hw::MachineConfig machine_config;
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, &spec, &machine_config));
  auto calibration = calib::LoadCalibration(spec.machine.calibration_path);
  if (!calibration.ok()) return calibration.status().Prefixed(job.path + ": machine.calibration");
  INSITU_ASSIGN_OR_RETURN(hw::Machine machine, hw::CreateMachine(machine_config));
  const hw::CameraInfo info = machine.camera->info();
  INSITU_RETURN_IF_ERROR(calib::CheckCameraMatches(calibration->camera, info.model, info.serial,
                                                   info.sensor_width_px, info.sensor_height_px)
                             .Prefixed(spec.machine.calibration_path));

  Report report;
  report.job = job.kind;
  report.started = NowIso8601();
  std::error_code ec;
  std::filesystem::create_directories(options.out_dir, ec);
  if (ec) return NotFound("cannot create output folder " + options.out_dir + ": " + ec.message());

  auto log = Logger("job");
  log->info("scan: {} lines x = {}..{} mm every {} mm, {} mm/s, exposure {} ms, calibration {}",
            spec.scan.line_count(), spec.scan.x_start_mm, spec.scan.x_end_mm,
            spec.scan.line_spacing_mm, spec.scan.speed_mm_per_s, spec.scan.exposure_ms,
            calibration->produced_by);
  Progress progress("job", "scan lines", spec.scan.line_count());
  auto scanned = RunScan(
      machine, spec.scan, spec.extraction, *calibration,
      [&](int done, int) { progress.Update(done); }, options.cancel);
  auto finish = [&](bool ok, const std::string& error) -> Result<Report> {
    report.ok = ok;
    report.error = error;
    report.elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    INSITU_RETURN_IF_ERROR(WriteReport(report, options.out_dir));
    if (!ok) return Status(StatusCode::kDeviceError, error);
    return report;
  };
  if (!scanned.ok()) return finish(false, scanned.status().ToString());
  const ScanStats& st = scanned->stats;
  const geometry::Cloud& cloud = scanned->cloud;

  const std::string ply = (std::filesystem::path(options.out_dir) / "cloud.ply").string();
  const Status saved = geometry::SaveCloudPly(cloud, ply);
  if (!saved.ok()) return finish(false, saved.ToString());
  report.artifacts["cloud"] = "cloud.ply";

  report.metrics["points"] = static_cast<double>(cloud.size());
  report.metrics["lines"] = st.lines;
  report.metrics["method"] = spec.method;
  report.metrics["valid_fraction"] =
      st.scan_lines_examined ? static_cast<double>(st.valid) / st.scan_lines_examined : 0.0;
  report.metrics["columns_none"] = static_cast<double>(st.none);
  report.metrics["columns_saturated"] = static_cast<double>(st.saturated);
  report.metrics["columns_two_peaks"] = static_cast<double>(st.two_peaks);
  report.metrics["columns_too_wide"] = static_cast<double>(st.too_wide);
  report.metrics["machine_time_s"] = st.machine_time_s;
  report.metrics["extract_time_ms_per_frame"] = st.lines ? st.extract_time_ms / st.lines : 0.0;
  if (st.saturated > 0) {
    report.warnings.push_back(std::to_string(st.saturated) +
                              " stripe columns saturated: lower camera.exposure_ms or gain");
  }

  if (spec.has_artifact) {
    auto eval = EvaluateStepGauge(cloud, spec.gauge);
    if (!eval.ok()) return finish(false, eval.status().ToString());
    report.metrics["height_error_max_abs_mm"] = eval->max_abs_error_mm;
    report.metrics["height_error_rms_mm"] = eval->rms_error_mm;
    report.metrics["length_mm"] = eval->length_mm;
    report.metrics["length_std_mm"] = eval->length_std_mm;
    report.metrics["length_error_mm"] = eval->length_mm - spec.gauge.length_mm;
    report.metrics["length_lines"] = eval->length_lines;
    report.metrics["gauge_points"] = eval->points;
    PlotSpec plot;
    plot.title = "Height error along the scan line, method " + std::to_string(spec.method) +
                 " (seed 000 Fig. 5b)";
    plot.x_label = "y (mm)";
    plot.y_label = "height error (mm)";
    for (size_t i = 0; i < eval->steps.size(); ++i) {
      const StepResult& s = eval->steps[i];
      const std::string name = "step_" + FormatMm(s.nominal_mm) + "mm";
      report.metrics["height_error_mean_mm_" + name] = s.mean_error_mm;
      report.metrics["height_error_max_abs_mm_" + name] = s.max_abs_error_mm;
      report.metrics["points_" + name] = s.points;
      if (s.points == 0) report.warnings.push_back("no scan point on " + name);
      plot.series.push_back({FormatMm(s.nominal_mm) + " mm step", s.bin_y_mm,
                             s.bin_mean_error_mm, PlotColor(static_cast<int>(i))});
    }
    const std::string png = (std::filesystem::path(options.out_dir) / "height_error.png").string();
    const Status plotted = SavePlotPng(plot, png);
    if (!plotted.ok()) return finish(false, plotted.ToString());
    report.artifacts["height_error"] = "height_error.png";
  }
  log->info("scan: {} points from {} lines", cloud.size(), st.lines);
  return finish(true, "");
}

}  // namespace

std::vector<std::string> JobKinds() { return {"scan", "calibrate"}; }

Result<Report> RunJob(const LoadedJob& job, const RunOptions& options) {
  if (job.kind == "scan") return RunScanJob(job, options);
  if (job.kind == "calibrate") return RunCalibrateJob(job, options);
  std::string kinds;
  for (const std::string& k : JobKinds()) kinds += (kinds.empty() ? "" : ", ") + k;
  return InvalidArgument(job.path + ": job: unknown kind '" + job.kind + "' (known: " + kinds + ")");
}

}  // namespace insitu::job
