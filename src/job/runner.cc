#include "insitu/job/runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "insitu/calib/calibration.h"
#include "insitu/core/log.h"
#include "insitu/geometry/cloud.h"
#include "insitu/inspect/insert.h"
#include "insitu/inspect/step_gauge.h"
#include "insitu/job/plot.h"
#include "insitu/job/scan.h"
#include "job/calibrate.h"
#include "job/field_calibration.h"
#include "job/insert_picture.h"
#include "job/inspect_grooves.h"
#include "job/machine_diagnosis.h"
#include "job/mark.h"
#include "job/phase.h"
#include "job/progress.h"
#include "job/scan_job.h"

namespace insitu::job {
namespace {

std::string FormatMm(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

// Gauge metrics under their report names; `suffix` tells methods apart ("_method1").
void AddGaugeMetrics(const inspect::StepGaugeResult& e, const inspect::StepGaugeSpec& gauge,
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
  for (const inspect::StepResult& s : e.steps) {
    const std::string name = "step_" + FormatMm(s.nominal_mm) + "mm" + suffix;
    m["height_error_mean_mm_" + name] = s.mean_error_mm;
    m["height_error_max_abs_mm_" + name] = s.max_abs_error_mm;
    m["points_" + name] = s.points;
    if (s.points == 0) report->warnings.push_back("no scan point on " + name);
  }
}

void AddGaugeSeries(const inspect::StepGaugeResult& e, const std::string& prefix, int first_color,
                    PlotSpec* plot) {
  for (size_t i = 0; i < e.steps.size(); ++i) {
    const inspect::StepResult& s = e.steps[i];
    plot->series.push_back({prefix + FormatMm(s.nominal_mm) + " mm step", s.bin_y_mm,
                            s.bin_mean_error_mm, PlotColor(first_color + static_cast<int>(i))});
  }
}

void AddStepMeans(const inspect::StepGaugeResult& e, const std::string& label, int rgb,
                  PlotSpec* plot) {
  PlotSeries series{label, {}, {}, rgb};
  for (const inspect::StepResult& s : e.steps) {
    series.x.push_back(s.nominal_mm);
    series.y.push_back(s.mean_error_mm);
  }
  plot->series.push_back(std::move(series));
}

// Seed 000 Table 1: the in-situ values against the nominal (vernier) ones.
void AddInsertMetrics(const inspect::InsertResult& r, const inspect::InsertSpec& s,
                      Report* report) {
  auto& m = report->metrics;
  double worst = 0.0;
  auto add = [&](const std::string& name, double value, double nominal) {
    m["insert_" + name + "_mm"] = value;
    m["insert_" + name + "_error_mm"] = value - nominal;
    worst = std::max(worst, std::abs(value - nominal));
  };
  add("thickness", r.thickness_mm, s.thickness_mm);
  for (int i = 0; i < 3; ++i) {
    add("edge_" + std::to_string(i + 1), r.edge_mm[i], s.edge_mm);
    m["insert_edge_" + std::to_string(i + 1) + "_raw_mm"] = r.edge_raw_mm[i];
  }
  add("hole_diameter", r.hole_diameter_mm, s.hole_diameter_mm);
  m["insert_error_max_abs_mm"] = worst;
  m["insert_plate_z_mm"] = r.plate_z_mm;
  m["insert_edge_fit_rms_mm"] = r.edge_fit_rms_mm;
  m["insert_edge_points_min"] =
      *std::min_element(r.edge_points.begin(), r.edge_points.end());
  m["insert_hole_points"] = r.hole_points;
  // Where the insert lies (for placing a pattern on it): the hole's centre.
  m["insert_hole_center_x_mm"] = r.hole_center_mm.x();
  m["insert_hole_center_y_mm"] = r.hole_center_mm.y();
  m["insert_hole_fit_rms_mm"] = r.hole_fit_rms_mm;
}

Status ReadScanKinds(const LoadedJob& job, ScanJobSpec* spec, hw::MachineConfig* machine_config) {
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, spec, machine_config, [&](ConfigReader& r) {
    ReadArtifact(r, spec);
  }));
  if (job.kind == "accuracy" && spec->artifact != "step_gauge") {
    return InvalidArgument(job.path + ": an accuracy job needs an artifact: of kind step_gauge");
  }
  return Status::Ok();
}

// Scan: the cloud and what the extraction saw, from a line scan over the part.
Result<ScanOutput> Scan(ScanMachine& up, const ScanJobSpec& spec, const RunOptions& options) {
  Logger("job")->info(
      "scan: {} lines x = {}..{} mm every {} mm, {} mm/s, exposure {} ms, calibration {}",
      spec.scan.line_count(), spec.scan.x_start_mm, spec.scan.x_end_mm, spec.scan.line_spacing_mm,
      spec.scan.speed_mm_per_s, spec.scan.exposure_ms, up.calibration.produced_by);
  PhaseProgress progress(options, "scan", "lines", spec.scan.line_count());
  ScanOptions scan = spec.scan;
  if (spec.save_frames) {
    scan.frames_dir = (std::filesystem::path(options.out_dir) / "frames").string();
    std::error_code error;
    std::filesystem::create_directories(scan.frames_dir, error);
    if (error) {
      return PhaseFailure(DeviceError("cannot create " + scan.frames_dir + ": " + error.message()));
    }
  }
  auto scanned = RunScan(
      up.machine, scan, spec.extraction, up.calibration,
      [&](int done, int) { progress.Update(done); }, options.cancel);
  if (!scanned.ok()) return PhaseFailure(scanned.status());
  return scanned;
}

// The cloud as cloud.ply, then the scan's metrics and warnings.
Status SaveScan(const ScanOutput& scanned, const ScanJobSpec& spec, const std::string& out_dir,
                Report* report) {
  const ScanStats& st = scanned.stats;
  const geometry::Cloud& cloud = scanned.cloud;
  const std::string ply = (std::filesystem::path(out_dir) / "cloud.ply").string();
  const Status saved = geometry::SaveCloudPly(cloud, ply);
  if (!saved.ok()) return PhaseFailure(saved);
  report->artifacts["cloud"] = "cloud.ply";

  auto& m = report->metrics;
  m["points"] = static_cast<double>(cloud.size());
  if (!cloud.empty()) {  // the centres' uncertainty from the local noise, typical point
    std::vector<float> sigma;
    sigma.reserve(cloud.size());
    for (const geometry::CloudPoint& p : cloud) sigma.push_back(p.center_sigma_px);
    std::nth_element(sigma.begin(), sigma.begin() + static_cast<ptrdiff_t>(sigma.size() / 2),
                     sigma.end());
    m["center_sigma_px_median"] = sigma[sigma.size() / 2];
  }
  m["lines"] = st.lines;
  m["method"] = spec.method;
  ReportScanLight(st, report);
  if (spec.method == 2) {
    m["points_outside_lookup"] = static_cast<double>(st.outside_lookup);
    if (st.outside_lookup > 0) {
      report->warnings.push_back(std::to_string(st.outside_lookup) +
                                 " stripe points fell outside the height calibration's volume "
                                 "and were left out");
    }
  }
  return Status::Ok();
}

// The job's artifact as judged on the scan (inspect); none when the job names none.
struct ArtifactEvaluation {
  std::optional<inspect::StepGaugeResult> gauge;          // the job's method
  std::optional<inspect::StepGaugeResult> gauge_method1;  // accuracy job: method 1
  std::optional<inspect::InsertResult> insert;
};

// Evaluates the artifact and puts its metrics (and warnings) in the report.
Result<ArtifactEvaluation> EvaluateArtifact(const std::string& job_kind, const ScanJobSpec& spec,
                                            const ScanOutput& scanned, Report* report) {
  ArtifactEvaluation e;
  if (spec.artifact == "step_gauge") {
    // The accuracy job compares both methods on the same frames (seed 000 Fig. 5).
    const bool both = job_kind == "accuracy";
    auto eval = inspect::EvaluateStepGauge(scanned.cloud, spec.gauge);
    if (!eval.ok()) return PhaseFailure(eval.status());
    AddGaugeMetrics(*eval, spec.gauge, "", report);
    e.gauge = std::move(*eval);
    if (both) {
      auto eval1 = inspect::EvaluateStepGauge(scanned.cloud_method1, spec.gauge);
      if (!eval1.ok()) return PhaseFailure(eval1.status());
      AddGaugeMetrics(*eval1, spec.gauge, "_method1", report);
      e.gauge_method1 = std::move(*eval1);
    }
  }
  if (spec.artifact == "insert") {
    auto eval = inspect::EvaluateInsert(scanned.cloud, spec.insert);
    if (!eval.ok()) return PhaseFailure(eval.status());
    AddInsertMetrics(*eval, spec.insert, report);
    e.insert = std::move(*eval);
  }
  return e;
}

// The step gauge's plots: the height error along the line (seed 000 Fig. 5b), and for the
// accuracy job both methods with the mean error per step (Fig. 5a).
Status WriteGaugePlots(const inspect::StepGaugeResult& eval,
                       const std::optional<inspect::StepGaugeResult>& eval1, int method,
                       const std::string& out_dir, Report* report) {
  const bool both = eval1.has_value();
  PlotSpec plot;
  plot.title = both ? "Height error along the scan line, methods 1 and 2 (seed 000 Fig. 5b)"
                    : "Height error along the scan line, method " + std::to_string(method) +
                          " (seed 000 Fig. 5b)";
  plot.x_label = "y (mm)";
  plot.y_label = "height error (mm)";
  AddGaugeSeries(eval, both ? "method 2, " : "", 0, &plot);
  PlotSpec heights;
  heights.title = "Mean height error per step (seed 000 Fig. 5a)";
  heights.x_label = "nominal step height (mm)";
  heights.y_label = "mean height error (mm)";
  heights.reference_y = {0.0};
  AddStepMeans(eval, "method " + std::to_string(method), PlotColor(1), &heights);
  if (both) {
    AddGaugeSeries(*eval1, "method 1, ", 4, &plot);
    AddStepMeans(*eval1, "method 1", PlotColor(0), &heights);
  }
  const std::filesystem::path dir(out_dir);
  const std::string name = both ? "accuracy.png" : "height_error.png";
  Status plotted = SavePlotPng(plot, (dir / name).string());
  if (plotted.ok() && both) plotted = SavePlotPng(heights, (dir / "step_heights.png").string());
  if (!plotted.ok()) return PhaseFailure(plotted);
  report->artifacts[both ? "accuracy" : "height_error"] = name;
  if (both) report->artifacts["step_heights"] = "step_heights.png";
  return Status::Ok();
}

// The insert's picture and the edge points behind its fits.
Status WriteInsertFiles(const geometry::Cloud& cloud, const inspect::InsertResult& eval,
                        const inspect::InsertSpec& spec, const std::string& out_dir,
                        Report* report) {
  const std::string name = "insert.png";
  const Status drawn =
      SaveInsertPicture(cloud, eval, spec, (std::filesystem::path(out_dir) / name).string());
  if (!drawn.ok()) return PhaseFailure(drawn);
  report->artifacts["insert"] = name;
  {
    // The edge points behind the fits, for checking them elsewhere.
    const std::string csv = (std::filesystem::path(out_dir) / "insert_edges.csv").string();
    std::ofstream f(csv);
    f << "kind,x_mm,y_mm\n";
    for (const auto& p : eval.outline_points) f << "outline," << p.x() << "," << p.y() << "\n";
    for (const auto& p : eval.hole_points_mm) f << "hole," << p.x() << "," << p.y() << "\n";
    if (!f.good()) return DeviceError("cannot write " + csv);
    report->artifacts["insert_edges"] = "insert_edges.csv";
  }
  Logger("job")->info(
      "insert: thickness {:.3f} mm, edges {:.3f} / {:.3f} / {:.3f} mm, hole {:.3f} mm",
      eval.thickness_mm, eval.edge_mm[0], eval.edge_mm[1], eval.edge_mm[2], eval.hole_diameter_mm);
  return Status::Ok();
}

// The artifact's figures and files beside the report.
Status WriteArtifactFiles(const ArtifactEvaluation& e, const ScanJobSpec& spec,
                          const geometry::Cloud& cloud, const std::string& out_dir,
                          Report* report) {
  if (e.gauge) {
    INSITU_RETURN_IF_ERROR(
        WriteGaugePlots(*e.gauge, e.gauge_method1, spec.method, out_dir, report));
  }
  if (e.insert)
    INSITU_RETURN_IF_ERROR(WriteInsertFiles(cloud, *e.insert, spec.insert, out_dir, report));
  return Status::Ok();
}

// The scan and accuracy jobs: bring the cell up, scan, judge the artifact, write its files.
Result<Report> RunScanJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ScanJobSpec spec;
  hw::MachineConfig machine_config;
  INSITU_RETURN_IF_ERROR(ReadScanKinds(job, &spec, &machine_config));
  INSITU_ASSIGN_OR_RETURN(ScanMachine up, BringUp(job, spec, machine_config, options));
  INSITU_ASSIGN_OR_RETURN(Report report,
                          StartReport(job.kind, options.out_dir, up.machine.warnings));
  // Once the cell is up, a phase's failure ends the job as a device error with its report.
  auto finish = [&](const Status& failure) {
    return FinishReport(report, failure.ok(), failure.message(), wall_start, options.out_dir,
                        StatusCode::kDeviceError);
  };

  auto scanned = Scan(up, spec, options);
  if (!scanned.ok()) return finish(scanned.status());
  if (const Status saved = SaveScan(*scanned, spec, options.out_dir, &report); !saved.ok()) {
    return finish(saved);
  }
  auto artifact = EvaluateArtifact(job.kind, spec, *scanned, &report);
  if (!artifact.ok()) return finish(artifact.status());
  const Status written =
      WriteArtifactFiles(*artifact, spec, scanned->cloud, options.out_dir, &report);
  if (!written.ok()) return finish(written);
  Logger("job")->info("scan: {} points from {} lines", scanned->cloud.size(), scanned->stats.lines);
  return finish(Status::Ok());
}

}  // namespace

namespace {

Status CheckScanJob(const LoadedJob& job) {
  ScanJobSpec spec;
  hw::MachineConfig machine_config;
  return ReadScanKinds(job, &spec, &machine_config);
}

// The text of `key` in `section` of the job, or `otherwise` (for the roles a job needs).
std::string Setting(const LoadedJob& job, const char* section, const char* key,
                    const std::string& otherwise) {
  const ConfigNode node = section[0] != '\0' ? job.root.Child(section).Child(key)
                                             : job.root.Child(key);
  if (!node.IsScalar()) return otherwise;
  auto text = node.AsString();
  return text.ok() ? *text : otherwise;
}

using Roles = std::vector<hw::Role>;
using hw::Role;

Roles ScanRoles(const LoadedJob&) { return {Role::kScanner, Role::kCamera}; }
Roles CalibrateRoles(const LoadedJob&) {
  return {Role::kScanner, Role::kCamera, Role::kStage, Role::kOperator};
}
Roles FieldRoles(const LoadedJob& job) {
  if (Setting(job, "", "route", "side") == "coaxial") {
    return {Role::kScanner, Role::kCamera, Role::kCoaxial};
  }
  return CalibrateRoles(job);
}
Roles DiagnoseMachineRoles(const LoadedJob&) {
  return {Role::kScanner, Role::kCamera, Role::kStage};
}
Roles ProfilerRoles(const LoadedJob&) { return {Role::kAxis, Role::kProfiler}; }
Roles GrooveRoles(const LoadedJob& job) {
  if (Setting(job, "inspect", "enabled", "true") == "false") return ScanRoles(job);
  return {Role::kScanner, Role::kCamera, Role::kAxis, Role::kProfiler};
}

// Every kind of job this build runs: its strict reading, the roles its cell must have, and its
// run.
struct JobKind {
  const char* name;
  Status (*check)(const LoadedJob&);
  Roles (*roles)(const LoadedJob&);
  Result<Report> (*run)(const LoadedJob&, const RunOptions&);
};

constexpr JobKind kJobKinds[] = {
    {"scan", CheckScanJob, ScanRoles, RunScanJob},
    {"accuracy", CheckScanJob, ScanRoles, RunScanJob},
    {"calibrate", CheckCalibrateJob, CalibrateRoles, RunCalibrateJob},
    {"field_calibration", CheckFieldCalibrationJob, FieldRoles, RunFieldCalibrationJob},
    {"mark", CheckMarkJob, ScanRoles, RunMarkJob},
    {"diagnose_machine", CheckDiagnoseMachineJob, DiagnoseMachineRoles, RunDiagnoseMachineJob},
    {"calibrate_profiler", CheckCalibrateProfilerJob, ProfilerRoles, RunCalibrateProfilerJob},
    {"inspect_grooves", CheckInspectGroovesJob, GrooveRoles, RunInspectGroovesJob},
};

// A role the job needs and its cell names no device for: refused before anything moves (the
// cell's devices themselves are opened when the job runs).
Status CheckRoles(const LoadedJob& job, const Roles& roles) {
  ConfigReader r(job.root);
  MachineSpec machine;
  ReadMachine(r, job.folder, &machine);
  for (Role role : roles) {
    if (hw::DeviceFor(machine.config, role) != "none") continue;
    return hw::MissingRole(role, job.path + ": the " + job.kind + " job",
                           hw::IsRealCell(machine.config));
  }
  return Status::Ok();
}

Result<const JobKind*> KindOf(const LoadedJob& job) {
  for (const JobKind& k : kJobKinds) {
    if (job.kind == k.name) return &k;
  }
  std::string kinds;
  for (const std::string& k : JobKinds()) kinds += (kinds.empty() ? "" : ", ") + k;
  return InvalidArgument(job.path + ": job: unknown kind '" + job.kind + "' (known: " + kinds + ")");
}

}  // namespace

std::vector<std::string> JobKinds() {
  std::vector<std::string> names;
  for (const JobKind& k : kJobKinds) names.push_back(k.name);
  return names;
}

Status CheckJob(const LoadedJob& job) {
  INSITU_ASSIGN_OR_RETURN(const JobKind* kind, KindOf(job));
  INSITU_RETURN_IF_ERROR(kind->check(job));
  return CheckRoles(job, kind->roles(job));
}

Result<Report> RunJob(const LoadedJob& job, const RunOptions& options) {
  if (options.cancel != nullptr && options.cancel->load()) {
    return Status(StatusCode::kCancelled, "cancelled before it started");
  }
  INSITU_ASSIGN_OR_RETURN(const JobKind* kind, KindOf(job));
  Result<Report> report = kind->run(job, options);
  // A job stopped by its cancel flag ends cancelled whatever phase it was in (a scan between
  // lines, a list the head aborted, a loop of profiles): the phase saw it as its own failure.
  if (!report.ok() && report.status().code() != StatusCode::kCancelled &&
      options.cancel != nullptr && options.cancel->load()) {
    return Status(StatusCode::kCancelled, report.status().message());
  }
  return report;
}

}  // namespace insitu::job
