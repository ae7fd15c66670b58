#include "job/mark.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "insitu/core/log.h"
#include "insitu/geometry/surface.h"
#include "insitu/pattern/codes.h"
#include "insitu/pattern/galvo_list.h"
#include "insitu/pattern/mark_plan.h"
#include "insitu/pattern/raster.h"
#include "insitu/pattern/vector.h"
#include "job/scan_job.h"

namespace insitu::job {
namespace {

struct PatternSpec {
  std::string kind;  // raster, qr, datamatrix, hpgl, svg, dxf
  std::string file;  // raster, hpgl, svg, dxf (resolved)
  std::string data;  // qr, datamatrix
  double pixel_mm = 0.05;  // raster pixel or code module
  int threshold = 128;
  bool invert = false;
  std::string qr_level = "M";
};

struct MarkJobSpec {
  PatternSpec pattern;
  pattern::Placement placement;
  double hatch_spacing_mm = 0.04;
  std::vector<double> hatch_angles_deg{0.0};
  bool outline = true;  // vector patterns: mark the paths too
  geometry::SurfaceOptions surface;
  pattern::MarkSettings laser;
  pattern::HeadFormat head;
  bool head_field_set = false, head_focus_set = false;  // else taken from the scan head
};

void ReadMarkSections(ConfigReader& r, const std::string& folder, MarkJobSpec* s) {
  ConfigReader& p = r.Section("pattern");
  p.Require("kind");
  p.ReadEnum("kind", &s->pattern.kind, {"raster", "qr", "datamatrix", "hpgl", "svg", "dxf"});
  const bool from_file =
      s->pattern.kind == "raster" || s->pattern.kind == "hpgl" || s->pattern.kind == "svg" ||
      s->pattern.kind == "dxf";
  if (p.ok()) p.Require(from_file ? "file" : "data");
  p.Read("file", &s->pattern.file);
  if (!s->pattern.file.empty()) s->pattern.file = ResolvePath(folder, s->pattern.file);
  p.Read("data", &s->pattern.data);
  if (!from_file || s->pattern.kind == "raster") {
    p.Read(s->pattern.kind == "raster" ? "pixel_mm" : "module_mm", &s->pattern.pixel_mm);
  }
  p.Read("threshold", &s->pattern.threshold);
  p.Read("invert", &s->pattern.invert);
  p.ReadEnum("error_correction", &s->pattern.qr_level, {"L", "M", "Q", "H"});
  if (p.ok() && !(s->pattern.pixel_mm > 0)) {
    p.Fail(s->pattern.kind == "raster" ? "pixel_mm" : "module_mm", "must be > 0");
  }
  ConfigReader& pl = r.Section("placement");
  pl.Read("scale", &s->placement.scale);
  pl.Read("rotation_deg", &s->placement.rotation_deg);
  pl.ReadArray("offset_mm", s->placement.offset_mm.data(), 2);
  if (pl.ok() && !(s->placement.scale > 0)) pl.Fail("scale", "must be > 0");
  ConfigReader& h = r.Section("hatch");
  h.Read("spacing_mm", &s->hatch_spacing_mm);
  h.Read("angles_deg", &s->hatch_angles_deg);
  h.Read("outline", &s->outline);
  if (h.ok() && !(s->hatch_spacing_mm > 0)) h.Fail("spacing_mm", "must be > 0");
  ConfigReader& su = r.Section("surface");
  su.Read("radius_mm", &s->surface.radius_mm);
  su.Read("min_points", &s->surface.min_points);
  su.Read("max_residual_mm", &s->surface.max_residual_mm);
  if (su.ok() && !(s->surface.radius_mm > 0)) su.Fail("radius_mm", "must be > 0");
  if (su.ok() && s->surface.min_points < 3) su.Fail("min_points", "must be >= 3");
  if (su.ok() && !(s->surface.max_residual_mm > 0)) su.Fail("max_residual_mm", "must be > 0");
  ConfigReader& l = r.Section("laser");
  pattern::MarkSettings& m = s->laser;
  l.Read("jump_speed_mm_per_s", &m.jump_speed_mm_per_s);
  l.Read("mark_speed_mm_per_s", &m.mark_speed_mm_per_s);
  l.Read("power", &m.laser_power);
  l.Read("frequency_khz", &m.laser_frequency_khz);
  l.Read("laser_on_delay_us", &m.laser_on_delay_us);
  l.Read("laser_off_delay_us", &m.laser_off_delay_us);
  l.Read("jump_delay_us", &m.jump_delay_us);
  l.Read("mark_delay_us", &m.mark_delay_us);
  l.Read("polygon_delay_us", &m.polygon_delay_us);
  l.Read("max_step_mm", &m.max_step_mm);
  l.Read("focus_offset_mm", &m.focus_offset_mm);
  if (l.ok()) l.FailFromValidate(m.Validate());
  ConfigReader& hd = r.Section("head");
  hd.Read("bits", &s->head.bits);
  s->head_field_set = hd.Has("field_half_size_mm");
  s->head_focus_set = hd.Has("focus_half_range_mm");
  hd.Read("field_half_size_mm", &s->head.field_half_size_mm);
  hd.Read("focus_half_range_mm", &s->head.focus_half_range_mm);
  if (hd.ok()) hd.FailFromValidate(s->head.Validate());
}

// The pattern's segments in pattern mm (before placement).
Result<std::vector<pattern::Segment2>> PatternSegments(const MarkJobSpec& s) {
  const PatternSpec& p = s.pattern;
  std::vector<pattern::Segment2> out;
  // The spacing is asked for on the part: hatch in pattern units, before the placement scales.
  const double spacing = s.hatch_spacing_mm / s.placement.scale;
  auto hatch_mask = [&](const pattern::Mask& mask) -> Status {
    for (double angle : s.hatch_angles_deg) {
      INSITU_ASSIGN_OR_RETURN(auto lines,
                              pattern::HatchMask(mask, p.pixel_mm, spacing, angle));
      out.insert(out.end(), lines.begin(), lines.end());
    }
    return Status::Ok();
  };
  if (p.kind == "raster") {
    INSITU_ASSIGN_OR_RETURN(auto mask, pattern::LoadRasterMask(p.file, p.threshold, p.invert));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else if (p.kind == "qr") {
    INSITU_ASSIGN_OR_RETURN(auto mask, pattern::QrCodeMask(p.data, p.qr_level[0]));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else if (p.kind == "datamatrix") {
    INSITU_ASSIGN_OR_RETURN(auto mask, pattern::DataMatrixMask(p.data));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else {
    INSITU_ASSIGN_OR_RETURN(auto vec, p.kind == "svg"   ? pattern::LoadSvg(p.file)
                                      : p.kind == "dxf" ? pattern::LoadDxf(p.file)
                                                        : pattern::LoadHpgl(p.file));
    bool closed = false;
    for (const auto& path : vec.paths) closed |= path.closed;
    if (closed) {
      for (double angle : s.hatch_angles_deg) {
        INSITU_ASSIGN_OR_RETURN(auto lines, pattern::HatchPolygons(vec, spacing, angle));
        out.insert(out.end(), lines.begin(), lines.end());
      }
    }
    if (s.outline || !closed) {
      const auto outline = pattern::Outline(vec);
      out.insert(out.end(), outline.begin(), outline.end());
    }
  }
  return out;
}

// The list's moves and settings for the scan head.
hw::GalvoList ToHeadList(const std::vector<pattern::ListCommand>& list) {
  hw::GalvoList out;
  for (const pattern::ListCommand& c : list) {
    switch (c.op) {
      case pattern::ListOp::kJumpAbs:
        out.entries.push_back({hw::GalvoListEntry::Kind::kJump, c.p});
        break;
      case pattern::ListOp::kMarkAbs:
        out.entries.push_back({hw::GalvoListEntry::Kind::kMark, c.p});
        break;
      case pattern::ListOp::kSetJumpSpeed: out.jump_speed_mm_per_s = c.a; break;
      case pattern::ListOp::kSetMarkSpeed: out.mark_speed_mm_per_s = c.a; break;
      case pattern::ListOp::kSetLaserDelays:
        out.laser_on_delay_us = std::max(0.0, c.a);
        out.laser_off_delay_us = c.b;
        break;
      case pattern::ListOp::kSetScannerDelays:
        out.jump_delay_us = c.a;
        out.mark_delay_us = c.b;
        break;
      case pattern::ListOp::kSetLaserPower: out.laser_power = c.a; break;
      case pattern::ListOp::kSetLaserFrequency: out.laser_frequency_khz = c.a; break;
      case pattern::ListOp::kEndOfList: break;
    }
  }
  return out;
}

// Disarms on every way out of the marking step.
struct ArmGuard {
  hw::Scanner* scanner;
  ~ArmGuard() { (void)scanner->Disarm(); }
};

}  // namespace

Result<Report> RunMarkJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ScanJobSpec spec;
  MarkJobSpec mark;
  hw::MachineConfig machine_config;
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, &spec, &machine_config, [&](ConfigReader& r) {
    ReadMarkSections(r, job.folder, &mark);
  }));
  // The pattern is read before the machine moves: a bad pattern file fails now.
  auto segments = PatternSegments(mark);
  if (!segments.ok()) return segments.status().Prefixed(job.path + ": pattern");
  if (segments->empty()) return InvalidArgument(job.path + ": pattern: nothing to mark");
  INSITU_ASSIGN_OR_RETURN(ScanMachine up, BringUp(job, spec, machine_config));
  {
    // The list's limits are the head's own unless the job narrows them.
    const hw::ScannerInfo head = up.machine.scanner->info();
    if (!mark.head_field_set && head.field_half_size_mm > 0) {
      mark.head.field_half_size_mm = head.field_half_size_mm;
    }
    if (!mark.head_focus_set && head.focus_range_mm > 0) {
      mark.head.focus_half_range_mm = head.focus_range_mm;
    }
    if (mark.head.field_half_size_mm > head.field_half_size_mm ||
        mark.head.focus_half_range_mm > head.focus_range_mm) {
      return InvalidArgument(job.path + ": head: limits beyond the scan head's own (field +-" +
                             std::to_string(head.field_half_size_mm) + " mm, focus +-" +
                             std::to_string(head.focus_range_mm) + " mm)");
    }
  }

  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir));
  const std::filesystem::path dir(options.out_dir);
  auto finish = [&](bool ok, const std::string& error) {
    return FinishReport(report, ok, error, wall_start, options.out_dir, StatusCode::kDeviceError);
  };
  auto log = Logger("job");

  // 1. Measure the part where it lies.
  log->info("mark: scanning {} lines", spec.scan.line_count());
  Progress progress("job", "scan lines", spec.scan.line_count());
  auto scanned = RunScan(
      up.machine, spec.scan, spec.extraction, up.calibration,
      [&](int done, int) { progress.Update(done); }, options.cancel);
  if (!scanned.ok()) return finish(false, scanned.status().ToString());
  const Status saved = geometry::SaveCloudPly(scanned->cloud, (dir / "cloud.ply").string());
  if (!saved.ok()) return finish(false, saved.ToString());
  report.artifacts["cloud"] = "cloud.ply";
  report.metrics["points"] = static_cast<double>(scanned->cloud.size());

  // 2. Put the pattern on the measured surface.
  if (mark.surface.radius_mm < spec.scan.line_spacing_mm) {
    report.warnings.push_back(
        "surface.radius_mm is smaller than the scan's line spacing: points between two scan "
        "lines find only one of them and get no height (set it to the spacing or more)");
  }
  auto surface = geometry::SurfaceModel::Build(scanned->cloud, mark.surface);
  if (!surface.ok()) return finish(false, surface.status().ToString());
  const std::vector<pattern::Segment2> placed = pattern::Place(*segments, mark.placement);
  pattern::MarkPlanReport plan;
  auto list = pattern::PlanMarking(placed, *surface, mark.laser, &plan);
  if (!list.ok()) return finish(false, list.status().ToString());
  report.metrics["pattern_segments"] = plan.segments;
  report.metrics["marks"] = plan.marks;
  report.metrics["marked_length_mm"] = plan.marked_length_mm;
  report.metrics["pattern_points"] = plan.points;
  report.metrics["points_without_surface"] = plan.points_without_surface;
  report.metrics["surface_z_min_mm"] = plan.z_min_mm;
  report.metrics["surface_z_max_mm"] = plan.z_max_mm;
  report.metrics["list_duration_s"] = pattern::ListDuration(*list);
  if (plan.points_without_surface > 0) {
    const Eigen::Vector2d& p = plan.unmarked_mm.front();
    char where[96];
    std::snprintf(where, sizeof where, " (the first at x = %.2f, y = %.2f mm)", p.x(), p.y());
    report.warnings.push_back(std::to_string(plan.points_without_surface) + " of " +
                              std::to_string(plan.points) +
                              " pattern points have no measured surface and are not marked" +
                              where);
  }

  // 3. The list in head units, every point checked against the field and the focus range.
  auto emitted = pattern::Emit(*list, mark.head);
  if (!emitted.ok()) return finish(false, "galvo list: " + emitted.status().ToString());
  {
    std::ofstream f(dir / "galvo_list.txt");
    f << pattern::FormatEmitted(*emitted, mark.head);
    if (!f.good()) return finish(false, "cannot write " + (dir / "galvo_list.txt").string());
  }
  report.artifacts["galvo_list"] = "galvo_list.txt";
  report.metrics["list_commands"] = static_cast<double>(emitted->size());

  // 4. Mark: armed only for the list.
  if (options.cancel != nullptr && options.cancel->load()) return finish(false, "cancelled");
  {
    const Status armed = up.machine.scanner->Arm();
    if (!armed.ok()) return finish(false, "arm: " + armed.ToString());
    ArmGuard guard{up.machine.scanner.get()};
    log->info("mark: {} marks, {:.1f} mm, ~{:.1f} s", plan.marks, plan.marked_length_mm,
              report.metrics["list_duration_s"]);
    const Status ran = up.machine.scanner->ExecuteList(ToHeadList(*list));
    if (!ran.ok()) return finish(false, "marking: " + ran.ToString());
  }
  log->info("mark: done");
  return finish(true, "");
}

}  // namespace insitu::job
