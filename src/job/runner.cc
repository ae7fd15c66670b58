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
  if (accuracy && !spec->has_artifact) {
    return InvalidArgument(job.path + ": an accuracy job needs an artifact: section");
  }
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

// Gauge metrics under their report names; `suffix` tells methods apart ("_method1").
void AddGaugeMetrics(const StepGaugeResult& e, const StepGaugeSpec& gauge,
                     const std::string& suffix, Report* report) {
  auto& m = report->metrics;
  m["height_error_max_abs_mm" + suffix] = e.max_abs_error_mm;
  m["height_error_rms_mm" + suffix] = e.rms_error_mm;
  m["height_error_max_abs_binned_mm" + suffix] = e.max_abs_binned_error_mm;
  m["length_mm" + suffix] = e.length_mm;
  m["length_std_mm" + suffix] = e.length_std_mm;
  m["length_error_mm" + suffix] = e.length_mm - gauge.length_mm;
  m["length_lines" + suffix] = e.length_lines;
  m["gauge_points" + suffix] = e.points;
  for (const StepResult& s : e.steps) {
    const std::string name = "step_" + FormatMm(s.nominal_mm) + "mm" + suffix;
    m["height_error_mean_mm_" + name] = s.mean_error_mm;
    m["height_error_max_abs_mm_" + name] = s.max_abs_error_mm;
    m["points_" + name] = s.points;
    if (s.points == 0) report->warnings.push_back("no scan point on " + name);
  }
}

void AddGaugeSeries(const StepGaugeResult& e, const std::string& prefix, int first_color,
                    PlotSpec* plot) {
  for (size_t i = 0; i < e.steps.size(); ++i) {
    const StepResult& s = e.steps[i];
    plot->series.push_back({prefix + FormatMm(s.nominal_mm) + " mm step", s.bin_y_mm,
                            s.bin_mean_error_mm, PlotColor(first_color + static_cast<int>(i))});
  }
}

void AddStepMeans(const StepGaugeResult& e, const std::string& label, int rgb, PlotSpec* plot) {
  PlotSeries series{label, {}, {}, rgb};
  for (const StepResult& s : e.steps) {
    series.x.push_back(s.nominal_mm);
    series.y.push_back(s.mean_error_mm);
  }
  plot->series.push_back(std::move(series));
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
  if (spec.method == 2) {
    report.metrics["points_outside_lookup"] = static_cast<double>(st.outside_lookup);
    if (st.outside_lookup > 0) {
      report.warnings.push_back(std::to_string(st.outside_lookup) +
                                " stripe points fell outside the height calibration's volume "
                                "and were left out");
    }
  }
  report.metrics["machine_time_s"] = st.machine_time_s;
  report.metrics["extract_time_ms_per_frame"] = st.lines ? st.extract_time_ms / st.lines : 0.0;
  if (st.saturated > 0) {
    report.warnings.push_back(std::to_string(st.saturated) +
                              " stripe columns saturated: lower camera.exposure_ms or gain");
  }

  if (spec.has_artifact) {
    // The accuracy job compares both methods on the same frames (seed 000 Fig. 5).
    const bool both = job.kind == "accuracy";
    auto eval = EvaluateStepGauge(cloud, spec.gauge);
    if (!eval.ok()) return finish(false, eval.status().ToString());
    AddGaugeMetrics(*eval, spec.gauge, "", &report);
    PlotSpec plot;
    plot.title = both ? "Height error along the scan line, methods 1 and 2 (seed 000 Fig. 5b)"
                      : "Height error along the scan line, method " +
                            std::to_string(spec.method) + " (seed 000 Fig. 5b)";
    plot.x_label = "y (mm)";
    plot.y_label = "height error (mm)";
    AddGaugeSeries(*eval, both ? "method 2, " : "", 0, &plot);
    PlotSpec heights;
    heights.title = "Mean height error per step (seed 000 Fig. 5a)";
    heights.x_label = "nominal step height (mm)";
    heights.y_label = "mean height error (mm)";
    heights.reference_y = {0.0};
    AddStepMeans(*eval, "method " + std::to_string(spec.method), PlotColor(1), &heights);
    if (both) {
      auto eval1 = EvaluateStepGauge(scanned->cloud_method1, spec.gauge);
      if (!eval1.ok()) return finish(false, eval1.status().ToString());
      AddGaugeMetrics(*eval1, spec.gauge, "_method1", &report);
      AddGaugeSeries(*eval1, "method 1, ", 4, &plot);
      AddStepMeans(*eval1, "method 1", PlotColor(0), &heights);
    }
    const std::filesystem::path dir(options.out_dir);
    const std::string name = both ? "accuracy.png" : "height_error.png";
    Status plotted = SavePlotPng(plot, (dir / name).string());
    if (plotted.ok() && both) plotted = SavePlotPng(heights, (dir / "step_heights.png").string());
    if (!plotted.ok()) return finish(false, plotted.ToString());
    report.artifacts[both ? "accuracy" : "height_error"] = name;
    if (both) report.artifacts["step_heights"] = "step_heights.png";
  }
  log->info("scan: {} points from {} lines", cloud.size(), st.lines);
  return finish(true, "");
}

}  // namespace

std::vector<std::string> JobKinds() { return {"scan", "accuracy", "calibrate"}; }

Result<Report> RunJob(const LoadedJob& job, const RunOptions& options) {
  if (job.kind == "scan" || job.kind == "accuracy") return RunScanJob(job, options);
  if (job.kind == "calibrate") return RunCalibrateJob(job, options);
  std::string kinds;
  for (const std::string& k : JobKinds()) kinds += (kinds.empty() ? "" : ", ") + k;
  return InvalidArgument(job.path + ": job: unknown kind '" + job.kind + "' (known: " + kinds + ")");
}

}  // namespace insitu::job
