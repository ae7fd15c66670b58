#include "job/mark.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "insitu/core/log.h"
#include "insitu/fit/extension.h"
#include "insitu/geometry/surface.h"
#include "insitu/pattern/codes.h"
#include "insitu/pattern/correction_table.h"
#include "insitu/pattern/galvo_list.h"
#include "insitu/pattern/mark_plan.h"
#include "insitu/pattern/path_opt.h"
#include "insitu/pattern/raster.h"
#include "insitu/pattern/text.h"
#include "insitu/pattern/vector.h"
#include "job/head_list.h"
#include "job/mark_verify.h"
#include "job/phase.h"
#include "job/progress.h"
#include "job/scan_job.h"

namespace insitu::job {
namespace {

struct PatternSpec {
  std::string kind;        // raster, qr, datamatrix, hpgl, svg, dxf, text
  std::string file;        // raster, hpgl, svg, dxf (resolved)
  std::string data;        // qr, datamatrix
  double pixel_mm = 0.05;  // raster pixel or code module
  int threshold = 128;
  bool invert = false;
  bool dither = false;  // raster: grey as a density of marked pixels
  std::string qr_level = "M";
  std::string text;               // text: what to write ('\n' starts a line)
  pattern::TextStyle text_style;  // text: font (outline or hershey:NAME), size, layout
};

// One pattern on the part: what, where, how it is filled.
struct ItemSpec {
  PatternSpec pattern;
  pattern::Placement placement;
  // placement.size_mm: the pattern scaled (uniformly) so its extents fit this width and
  // height on the part; a 0 leaves that side free. Replaces placement.scale.
  Eigen::Vector2d size_mm = Eigen::Vector2d::Zero();
  double hatch_spacing_mm = 0.04;
  std::vector<double> hatch_angles_deg{0.0};
  bool outline = true;  // vector patterns: mark the paths too
  // Which point of the pattern the placement's offset puts on the part: the
  // file's origin (vector files) or the centre of its bounding box. Codes and
  // rasters are always centred.
  std::string anchor = "origin";
  // project: straight down onto the surface; wrap: equal arc length on it (seed
  // 000 case 3).
  std::string mapping = "project";
  // Vector outlines through seed 004's path optimisation, within max_error_mm
  // on the part.
  bool optimise_paths = true;
  double path_max_error_mm = 0.002;
  std::string path_placement = "band";  // band: chords straddle the curve; curve: on it
};

// What path optimisation did to an item's outlines, and what its file held that was not
// drawn (nothing is dropped silently: each kind is a warning and a metric).
struct PathStats {
  int input_points = 0, mark_points = 0;
  double max_error_mm = 0.0;
  double jump_mm = 0.0,
         jump_file_mm = 0.0;  // outline jumps in travel and file order
  int texts = 0;
  std::map<std::string, int> skipped;  // by kind
  std::vector<std::string> warnings;
};

struct MarkJobSpec {
  std::vector<ItemSpec> items;
  geometry::SurfaceOptions surface;
  pattern::MarkSettings laser;
  pattern::HeadFormat head;
  bool head_field_set = false,
       head_focus_set = false;  // else taken from the scan head
  std::string correction_file;  // field correction table (resolved), empty: none
  std::string extension_file;   // model extension from insitu diagnose (resolved), empty: none
  VerifyOptions verify;
  double spot_diameter_mm = 0.04;  // the marking beam's 1/e^2 diameter at focus (lens data)
};

// pattern, placement and hatch of one item, from `r` (the job's root or an
// element of items).
void ReadItem(ConfigReader& r, const std::string& folder, ItemSpec* s) {
  ConfigReader& p = r.Section("pattern");
  p.Require("kind");
  p.ReadEnum("kind", &s->pattern.kind,
             {"raster", "qr", "datamatrix", "hpgl", "svg", "dxf", "text"});
  const bool from_file = s->pattern.kind == "raster" || s->pattern.kind == "hpgl" ||
                         s->pattern.kind == "svg" || s->pattern.kind == "dxf";
  const bool text = s->pattern.kind == "text";
  if (p.ok()) p.Require(from_file ? "file" : text ? "text" : "data");
  if (text) {
    pattern::TextStyle& t = s->pattern.text_style;
    p.Read("text", &s->pattern.text);
    p.Read("font", &t.font);
    p.Read("height_mm", &t.height_mm);
    p.Read("size_is_em", &t.size_is_em);
    p.Read("letter_spacing_mm", &t.letter_spacing_mm);
    p.Read("line_spacing", &t.line_spacing);
    std::string align = "left";
    p.ReadEnum("align", &align, {"left", "center", "right"});
    t.align = align == "left"     ? pattern::TextAlign::kLeft
              : align == "center" ? pattern::TextAlign::kCenter
                                  : pattern::TextAlign::kRight;
    p.Read("arc_radius_mm", &t.arc_radius_mm);
    if (p.ok()) p.FailFromValidate(t.Validate());
    if (p.ok() && s->pattern.text.empty()) p.Fail("text", "must not be empty");
  }
  p.Read("file", &s->pattern.file);
  if (!s->pattern.file.empty()) s->pattern.file = ResolvePath(folder, s->pattern.file);
  p.Read("data", &s->pattern.data);
  if (!from_file || s->pattern.kind == "raster") {
    p.Read(s->pattern.kind == "raster" ? "pixel_mm" : "module_mm", &s->pattern.pixel_mm);
  }
  p.Read("threshold", &s->pattern.threshold);
  p.Read("invert", &s->pattern.invert);
  if (s->pattern.kind == "raster") p.Read("dither", &s->pattern.dither);
  p.ReadEnum("error_correction", &s->pattern.qr_level, {"L", "M", "Q", "H"});
  if (p.ok() && !(s->pattern.pixel_mm > 0)) {
    p.Fail(s->pattern.kind == "raster" ? "pixel_mm" : "module_mm", "must be > 0");
  }
  ConfigReader& pl = r.Section("placement");
  pl.Read("scale", &s->placement.scale);
  if (pl.Has("size_mm")) {
    if (pl.Has("scale")) pl.Fail("size_mm", "give either scale or size_mm, not both");
    pl.ReadArray("size_mm", s->size_mm.data(), 2);
    if (pl.ok() && !(s->size_mm.minCoeff() >= 0 && s->size_mm.maxCoeff() > 0 &&
                     s->size_mm.allFinite())) {
      pl.Fail("size_mm", "must be [width, height] in mm, >= 0 each (0: that side free), not both 0");
    }
  }
  pl.Read("rotation_deg", &s->placement.rotation_deg);
  pl.ReadArray("offset_mm", s->placement.offset_mm.data(), 2);
  pl.ReadEnum("anchor", &s->anchor, {"origin", "centre"});
  pl.ReadEnum("mapping", &s->mapping, {"project", "wrap"});
  if (pl.ok() && !(s->placement.scale > 0)) pl.Fail("scale", "must be > 0");
  ConfigReader& h = r.Section("hatch");
  h.Read("spacing_mm", &s->hatch_spacing_mm);
  h.Read("angles_deg", &s->hatch_angles_deg);
  h.Read("outline", &s->outline);
  if (h.ok() && !(s->hatch_spacing_mm > 0)) h.Fail("spacing_mm", "must be > 0");
}

void ReadMarkSections(ConfigReader& r, const std::string& folder, MarkJobSpec* s) {
  if (r.Has("items")) {
    // Several patterns marked from one scan: a list of {pattern, placement,
    // hatch}.
    r.Skip("items");
    const ConfigNode items = r.node().Child("items");
    if (!items.IsSequence() || items.size() == 0) {
      r.Fail("items", "must be a non-empty list of {pattern, placement, hatch}");
      return;
    }
    for (size_t i = 0; i < items.size(); ++i) {
      if (!items.At(i).IsMap()) {
        r.Fail("items", "element " + std::to_string(i) + " is not a map");
        return;
      }
      ConfigReader ir(items.At(i));
      ItemSpec item;
      ReadItem(ir, folder, &item);
      const Status st = ir.Finish();
      if (!st.ok()) {
        r.Fail("items", st.message());
        return;
      }
      s->items.push_back(item);
    }
  } else {
    s->items.emplace_back();
    ReadItem(r, folder, &s->items.back());
  }
  // Path optimisation of vector outlines: one setting for every item.
  ConfigReader& po = r.Section("path");
  ItemSpec defaults;
  po.Read("optimise", &defaults.optimise_paths);
  po.Read("max_error_mm", &defaults.path_max_error_mm);
  po.ReadEnum("placement", &defaults.path_placement, {"band", "curve"});
  if (po.ok() && !(defaults.path_max_error_mm > 0)) po.Fail("max_error_mm", "must be > 0");
  for (ItemSpec& item : s->items) {
    item.optimise_paths = defaults.optimise_paths;
    item.path_max_error_mm = defaults.path_max_error_mm;
    item.path_placement = defaults.path_placement;
  }
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
  l.Read("spot_diameter_mm", &s->spot_diameter_mm);
  if (l.ok() && !(s->spot_diameter_mm > 0)) l.Fail("spot_diameter_mm", "must be > 0");
  if (l.ok()) l.FailFromValidate(m.Validate());
  ConfigReader& hd = r.Section("head");
  hd.Read("bits", &s->head.bits);
  s->head_field_set = hd.Has("field_half_size_mm");
  s->head_focus_set = hd.Has("focus_half_range_mm");
  hd.Read("field_half_size_mm", &s->head.field_half_size_mm);
  hd.Read("focus_half_range_mm", &s->head.focus_half_range_mm);
  hd.Read("correction", &s->correction_file);
  if (!s->correction_file.empty()) s->correction_file = ResolvePath(folder, s->correction_file);
  hd.Read("model_extension", &s->extension_file);
  if (!s->extension_file.empty()) s->extension_file = ResolvePath(folder, s->extension_file);
  if (hd.ok() && !s->correction_file.empty() && !s->extension_file.empty()) {
    hd.Fail("model_extension", "give either a correction table or a model extension, not both");
  }
  if (hd.ok()) hd.FailFromValidate(s->head.Validate());
  ConfigReader& v = r.Section("verify");
  VerifyOptions& vo = s->verify;
  v.Read("enabled", &vo.enabled);
  v.Read("coaxial_pixel_um", &vo.coaxial_pixel_um);
  v.Read("coaxial_rotation_deg", &vo.coaxial_rotation_deg);
  v.Read("coaxial_exposure_ms", &vo.coaxial_exposure_ms);
  v.Read("spacing_spots", &vo.spacing_spots);
  v.Read("focus_points", &vo.focus_points);
  v.Read("focus_sweep_mm", &vo.focus_sweep_mm);
  v.Read("focus_step_mm", &vo.focus_step_mm);
  v.Read("side_target_level", &vo.side_target_level);
  if (v.ok()) v.FailFromValidate(vo.Validate());
}

// The uniform scale that fits extents `w` x `h` (mm, before placement) into size_mm (a 0
// side is free). Errors: invalid_argument for a pattern with no extent along a side asked for.
Result<double> FitScale(const Eigen::Vector2d& size_mm, double w, double h) {
  double scale = std::numeric_limits<double>::infinity();
  if (size_mm.x() > 0) {
    if (!(w > 0)) return InvalidArgument("placement.size_mm: the pattern has no width to fit");
    scale = std::min(scale, size_mm.x() / w);
  }
  if (size_mm.y() > 0) {
    if (!(h > 0)) return InvalidArgument("placement.size_mm: the pattern has no height to fit");
    scale = std::min(scale, size_mm.y() / h);
  }
  return scale;
}

// The item's vector pattern: its file, or its text laid out in a font, curves flattened to
// within `tolerance_mm` in pattern units.
Result<pattern::VectorPattern> LoadVector(const PatternSpec& p, double tolerance_mm) {
  if (p.kind == "text") return pattern::RenderText(p.text, p.text_style, tolerance_mm);
  if (p.kind == "svg") return pattern::LoadSvg(p.file, tolerance_mm);
  if (p.kind == "dxf") return pattern::LoadDxf(p.file, tolerance_mm);
  return pattern::LoadHpgl(p.file);
}

// Curves are flattened to within 5 um on the part: in pattern units, that over the scale.
constexpr double kFlattenMm = 0.005;

// The pattern's segments in pattern mm (before placement); with placement.size_mm the item's
// placement.scale is set here, from the pattern's extents. Vector outlines go through path
// optimisation (seed 004) and into travel order; *stats says what that did and what the file
// held that was not drawn.
Result<std::vector<pattern::Segment2>> PatternSegments(ItemSpec* item, PathStats* stats) {
  *stats = PathStats{};
  ItemSpec& s = *item;
  const PatternSpec& p = s.pattern;
  const bool fit = s.size_mm.maxCoeff() > 0;
  std::vector<pattern::Segment2> out;
  // The spacing is asked for on the part: hatch in pattern units, before the
  // placement scales.
  auto hatch_mask = [&](const pattern::Mask& mask) -> Status {
    if (fit) {
      INSITU_ASSIGN_OR_RETURN(s.placement.scale, FitScale(s.size_mm, mask.width * p.pixel_mm,
                                                          mask.height * p.pixel_mm));
    }
    const double spacing = s.hatch_spacing_mm / s.placement.scale;
    for (double angle : s.hatch_angles_deg) {
      INSITU_ASSIGN_OR_RETURN(auto lines, pattern::HatchMask(mask, p.pixel_mm, spacing, angle));
      out.insert(out.end(), lines.begin(), lines.end());
    }
    return Status::Ok();
  };
  if (p.kind == "raster") {
    INSITU_ASSIGN_OR_RETURN(auto mask,
                            pattern::LoadRasterMask(p.file, p.threshold, p.invert, p.dither));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else if (p.kind == "qr") {
    INSITU_ASSIGN_OR_RETURN(auto mask, pattern::QrCodeMask(p.data, p.qr_level[0]));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else if (p.kind == "datamatrix") {
    INSITU_ASSIGN_OR_RETURN(auto mask, pattern::DataMatrixMask(p.data));
    INSITU_RETURN_IF_ERROR(hatch_mask(mask));
  } else {
    INSITU_ASSIGN_OR_RETURN(pattern::VectorPattern vec,
                            LoadVector(p, kFlattenMm / s.placement.scale));
    if (fit) {
      Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
      Eigen::Vector2d hi = -lo;
      for (const auto& path : vec.paths) {
        for (const Eigen::Vector2d& q : path.points) {
          lo = lo.cwiseMin(q);
          hi = hi.cwiseMax(q);
        }
      }
      INSITU_ASSIGN_OR_RETURN(s.placement.scale,
                              FitScale(s.size_mm, hi.x() - lo.x(), hi.y() - lo.y()));
      // Enlarged: flattened again, finer, so the chords stay within 5 um on the part.
      if (s.placement.scale > 1.0) {
        INSITU_ASSIGN_OR_RETURN(vec, LoadVector(p, kFlattenMm / s.placement.scale));
      }
    }
    stats->texts = vec.texts;
    stats->skipped = vec.skipped;
    stats->warnings = vec.warnings;
    const double spacing = s.hatch_spacing_mm / s.placement.scale;
    bool closed = false;
    for (const auto& path : vec.paths) closed |= path.closed;
    if (closed) {
      for (double angle : s.hatch_angles_deg) {
        INSITU_ASSIGN_OR_RETURN(auto lines, pattern::HatchPolygons(vec, spacing, angle));
        out.insert(out.end(), lines.begin(), lines.end());
      }
    }
    if (s.outline || !closed) {
      if (s.optimise_paths) {
        // The error is asked for on the part: the fit works in pattern units at
        // the placement's scale, and its mark points go back to pattern units
        // for Place().
        pattern::PathOptOptions o =
            pattern::PathOptOptions::ForErrorBudget(s.placement.scale, s.path_max_error_mm);
        o.placement = s.path_placement == "band"
                          ? pattern::PathOptOptions::Placement::kToleranceBand
                          : pattern::PathOptOptions::Placement::kOnCurve;
        for (pattern::Polyline& path : vec.paths) {
          if (path.points.size() < 3) continue;
          stats->input_points += static_cast<int>(path.points.size());
          auto opt = pattern::OptimisePolyline(path, o);
          if (!opt.ok()) return opt.status();
          for (Eigen::Vector2d& q : opt->marks.points) q /= s.placement.scale;
          path.points = std::move(opt->marks.points);
          stats->mark_points += static_cast<int>(path.points.size());
          stats->max_error_mm = std::max(stats->max_error_mm, opt->summary.max_error_mm);
        }
      }
      const Eigen::Vector2d start = out.empty() ? Eigen::Vector2d::Zero() : out.back().b;
      stats->jump_mm = pattern::OrderForTravel(&vec, start, &stats->jump_file_mm);
      const auto outline = pattern::Outline(vec);
      out.insert(out.end(), outline.begin(), outline.end());
    }
  }
  return out;
}

// The items placed on the part in plan (galvo xy, mm), before the surface is known.
struct Patterns {
  std::vector<std::vector<pattern::Segment2>> placed_items;  // one per item
  PathStats paths;                                           // over all items
};

// Reads, fills and places every item's pattern. Errors name the item's pattern in the job file.
Result<Patterns> LoadPatterns(const MarkJobSpec& mark, const std::string& job_path) {
  Patterns out;
  PathStats& paths = out.paths;
  for (size_t i = 0; i < mark.items.size(); ++i) {
    const std::string where =
        mark.items.size() > 1 ? ": items[" + std::to_string(i) + "].pattern" : ": pattern";
    PathStats st;
    ItemSpec item = mark.items[i];  // its placement.scale set by size_mm
    auto segments = PatternSegments(&item, &st);
    if (!segments.ok()) return segments.status().Prefixed(job_path + where);
    paths.input_points += st.input_points;
    paths.mark_points += st.mark_points;
    paths.max_error_mm = std::max(paths.max_error_mm, st.max_error_mm);
    paths.jump_mm += st.jump_mm * item.placement.scale;
    paths.jump_file_mm += st.jump_file_mm * item.placement.scale;
    paths.texts += st.texts;
    for (const auto& [kind, n] : st.skipped) paths.skipped[kind] += n;
    for (const std::string& w : st.warnings) paths.warnings.push_back(where.substr(2) + ": " + w);
    if (segments->empty()) return InvalidArgument(job_path + where + ": nothing to mark");
    if (item.anchor == "centre") {
      Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
      for (const auto& sg : *segments) {
        lo = lo.cwiseMin(sg.a.cwiseMin(sg.b));
        hi = hi.cwiseMax(sg.a.cwiseMax(sg.b));
      }
      const Eigen::Vector2d mid = 0.5 * (lo + hi);
      for (auto& sg : *segments) sg.a -= mid, sg.b -= mid;
    }
    out.placed_items.push_back(pattern::Place(*segments, item.placement));
  }
  return out;
}

// The field correction the job file names (head.correction or head.model_extension); empty
// when it names none.
Result<pattern::FieldCorrection> LoadCorrection(const MarkJobSpec& mark,
                                                const std::string& job_path) {
  pattern::FieldCorrection correction;
  if (!mark.correction_file.empty()) {
    auto table = pattern::CorrectionTable::Load(mark.correction_file);
    if (!table.ok()) return table.status().Prefixed(job_path + ": head.correction");
    correction = table->AsFieldCorrection();
  }
  if (!mark.extension_file.empty()) {
    // The diagnosed model of where commands land: every point is sent as the command that
    // lands on it.
    auto ext = fit::LoadExtension(mark.extension_file);
    if (!ext.ok()) return ext.status().Prefixed(job_path + ": head.model_extension");
    correction = [e = *ext](const Eigen::Vector3d& p) {
      const Eigen::Vector2d c = e.Inverse(p.head<2>(), p.z());
      return Eigen::Vector3d(c.x(), c.y(), p.z());
    };
  }
  return correction;
}

// The scan head as the calibration knows it: the marking beam's direction, and the measured
// head's correction unless the job file names its own. Returns true when the job's correction
// is used in place of a head the calibration measured.
bool UseCalibratedHead(const calib::CalibrationSet& calibration, MarkJobSpec* mark,
                       pattern::FieldCorrection* correction) {
  // A focus offset is taken along the marking beam (pattern::MarkSettings::beam_up).
  mark->laser.beam_up = [head = calibration.head.model](const Eigen::Vector3d& cmd) {
    optics::ChiefRay ray;
    return head.Land(cmd, {}, &ray) ? ray.up : Eigen::Vector3d(Eigen::Vector3d::UnitZ());
  };
  if (!*correction && calibration.head.measured) {
    *correction = MeasuredHeadCorrection(calibration);
  } else if (*correction && calibration.head.measured) {
    return true;
  }
  return false;
}

// The list's limits are the head's own unless the job narrows them; never beyond them.
Status FitHeadLimits(const hw::ScannerInfo& head, const std::string& job_path, MarkJobSpec* mark) {
  if (!mark->head_field_set && head.field_half_size_mm > 0) {
    mark->head.field_half_size_mm = head.field_half_size_mm;
  }
  if (!mark->head_focus_set && head.focus_range_mm > 0) {
    mark->head.focus_half_range_mm = head.focus_range_mm;
  }
  if (mark->head.field_half_size_mm > head.field_half_size_mm ||
      mark->head.focus_half_range_mm > head.focus_range_mm) {
    return InvalidArgument(job_path + ": head: limits beyond the scan head's own (field +-" +
                           std::to_string(head.field_half_size_mm) + " mm, focus +-" +
                           std::to_string(head.focus_range_mm) + " mm)");
  }
  return Status::Ok();
}

// What every phase of a mark job after bring-up works with.
struct MarkRun {
  const ScanJobSpec& spec;
  const MarkJobSpec& mark;
  const RunOptions& options;
  ScanMachine& up;
  Report& report;
  std::filesystem::path dir;  // the job's output folder
};

bool Cancelled(const RunOptions& options) {
  return options.cancel != nullptr && options.cancel->load();
}

// 1. Measure the part where it lies.
Result<ScanOutput> ScanPart(MarkRun& run) {
  Logger("job")->info("mark: scanning {} lines", run.spec.scan.line_count());
  PhaseProgress progress(run.options, "scan", "lines", run.spec.scan.line_count());
  auto scanned = RunScan(
      run.up.machine, run.spec.scan, run.spec.extraction, run.up.calibration,
      [&](int done, int) { progress.Update(done); }, run.options.cancel);
  if (!scanned.ok()) return PhaseFailure(scanned.status());
  const Status saved = geometry::SaveCloudPly(scanned->cloud, (run.dir / "cloud.ply").string());
  if (!saved.ok()) return PhaseFailure(saved);
  run.report.artifacts["cloud"] = "cloud.ply";
  run.report.metrics["points"] = static_cast<double>(scanned->cloud.size());
  ReportScanLight(scanned->stats, &run.report);
  return scanned;
}

// 2. Put the pattern on the measured surface: the surface from the cloud, the items mapped
// onto it by wrapping (seed 000 case 3) where they ask for it.
Result<geometry::SurfaceModel> Place(MarkRun& run, const geometry::Cloud& cloud,
                                     std::vector<std::vector<pattern::Segment2>>* placed_items) {
  const MarkJobSpec& mark = run.mark;
  if (mark.surface.radius_mm < run.spec.scan.line_spacing_mm) {
    run.report.warnings.push_back(
        "surface.radius_mm is smaller than the scan's "
        "line spacing: points between two scan "
        "lines find only one of them and get no height "
        "(set it to the spacing or more)");
  }
  auto surface = geometry::SurfaceModel::Build(cloud, mark.surface);
  if (!surface.ok()) return PhaseFailure(surface.status());
  for (size_t i = 0; i < mark.items.size(); ++i) {
    if (mark.items[i].mapping != "wrap") continue;
    auto wrapped = pattern::WrapOnSurface((*placed_items)[i], mark.items[i].placement.offset_mm,
                                          *surface, mark.laser.max_step_mm);
    if (!wrapped.ok()) return PhaseFailure(wrapped.status(), "item " + std::to_string(i) + ": ");
    (*placed_items)[i] = std::move(*wrapped);
  }
  return surface;
}

// The marking list on the surface, with what planning it did and what it could not mark.
Result<std::vector<pattern::ListCommand>> Plan(
    MarkRun& run, const geometry::SurfaceModel& surface,
    const std::vector<std::vector<pattern::Segment2>>& placed_items, const PathStats& paths,
    pattern::MarkPlanReport* plan) {
  const MarkJobSpec& mark = run.mark;
  Report& report = run.report;
  std::vector<pattern::Segment2> placed;
  for (const auto& item : placed_items) placed.insert(placed.end(), item.begin(), item.end());
  auto list = pattern::PlanMarking(placed, surface, mark.laser, plan);
  if (!list.ok()) return PhaseFailure(list.status());
  report.metrics["pattern_segments"] = plan->segments;
  report.metrics["marks"] = plan->marks;
  report.metrics["marked_length_mm"] = plan->marked_length_mm;
  report.metrics["pattern_points"] = plan->points;
  report.metrics["points_without_surface"] = plan->points_without_surface;
  report.metrics["surface_z_min_mm"] = plan->z_min_mm;
  report.metrics["surface_z_max_mm"] = plan->z_max_mm;
  report.metrics["list_duration_s"] = pattern::ListDuration(*list);
  if (paths.jump_file_mm > 0) {
    report.metrics["outline_jump_mm"] = paths.jump_mm;
    report.metrics["outline_jump_mm_file_order"] = paths.jump_file_mm;
  }
  // What the drawings held and the job does not mark: never silent.
  report.metrics["pattern_texts"] = paths.texts;
  // A kind each, up to 32 (a file may name any number of entity types): the rest as "other".
  int kinds = 0, other = 0;
  for (const auto& [kind, n] : paths.skipped) {
    if (++kinds > 32) {
      other += n;
      continue;
    }
    report.metrics["pattern_skipped_" + kind] = n;
    report.warnings.push_back("pattern: " + std::to_string(n) + " " + kind +
                              (n == 1 ? " was" : " were") + " not drawn (not marked)");
  }
  if (other > 0) {
    report.metrics["pattern_skipped_other"] = other;
    report.warnings.push_back("pattern: " + std::to_string(other) +
                              " more entities of other kinds were not drawn (not marked)");
  }
  for (const std::string& w : paths.warnings) report.warnings.push_back(w);
  if (paths.input_points > 0) {
    report.metrics["path_points_in"] = paths.input_points;
    report.metrics["path_points_out"] = paths.mark_points;
    report.metrics["path_max_error_um"] = paths.max_error_mm * 1e3;
  }
  for (const ItemSpec& it : mark.items) {
    if (!it.hatch_angles_deg.empty() && it.hatch_spacing_mm < mark.spot_diameter_mm) {
      report.warnings.push_back("hatch spacing " + std::to_string(it.hatch_spacing_mm) +
                                " mm is below the " + std::to_string(mark.spot_diameter_mm) +
                                " mm spot: neighbouring lines overlap, every area is marked more "
                                "than once (more "
                                "heat, deeper marks)");
    }
  }
  if (plan->points_without_surface > 0) {
    const Eigen::Vector2d& p = plan->unmarked_mm.front();
    char where[96];
    std::snprintf(where, sizeof where, " (the first at x = %.2f, y = %.2f mm)", p.x(), p.y());
    report.warnings.push_back(
        std::to_string(plan->points_without_surface) + " of " + std::to_string(plan->points) +
        " pattern points have no measured surface and are not marked" + where);
  }
  return list;
}

// 3. The list in head units, every point checked against the field and the
// focus range.
Status Emit(MarkRun& run, const std::vector<pattern::ListCommand>& list,
            const pattern::FieldCorrection& correction) {
  auto emitted = pattern::Emit(list, run.mark.head, correction);
  if (!emitted.ok()) return PhaseFailure(emitted.status(), "galvo list: ");
  {
    std::ofstream f(run.dir / "galvo_list.txt");
    f << pattern::FormatEmitted(*emitted, run.mark.head);
    if (!f.good()) return DeviceError("cannot write " + (run.dir / "galvo_list.txt").string());
  }
  run.report.artifacts["galvo_list"] = "galvo_list.txt";
  run.report.metrics["list_commands"] = static_cast<double>(emitted->size());
  return Status::Ok();
}

// The side camera's frame before marking and its exposure, kept for the frame after
// (nothing when verification is off).
struct SideBefore {
  Frame frame;
  double exposure_us = 0.0;
};

// 4. Mark: armed only for the list. The side camera looks first, for the
// comparison after.
Result<SideBefore> Mark(MarkRun& run, const std::vector<pattern::ListCommand>& list,
                        const pattern::MarkPlanReport& plan,
                        const pattern::FieldCorrection& correction) {
  hw::Machine& machine = run.up.machine;
  if (Cancelled(run.options)) return Status(StatusCode::kCancelled, "cancelled");
  SideBefore before;
  if (run.mark.verify.enabled) {
    auto f = GrabSideView(machine, run.mark.verify, &before.exposure_us);
    if (!f.ok()) return PhaseFailure(f.status(), "side camera before marking: ");
    before.frame = std::move(*f);
  }
  auto log = Logger("job");
  {
    const Status armed = machine.scanner->Arm();
    if (!armed.ok()) return PhaseFailure(armed, "arm: ");
    ArmGuard guard{machine.scanner.get()};
    log->info("mark: {} marks, {:.1f} mm, ~{:.1f} s", plan.marks, plan.marked_length_mm,
              run.report.metrics["list_duration_s"]);
    // Cancel reaches the head while the list runs: it aborts within one of its clock ticks.
    const double list_ms = std::round(run.report.metrics["list_duration_s"] * 1e3);
    PhaseProgress marking(run.options, "mark", "ms", list_ms);
    hw::ListControl control;
    control.abort = run.options.cancel;
    control.progress = [&](double fraction) { marking.Update(std::round(fraction * list_ms)); };
    const Status ran = machine.scanner->ExecuteList(ToHeadList(list, correction), control);
    // A controller with its own list format (an LMC board): galvo_list.txt is what it received.
    if (const std::string received = machine.scanner->ReceivedList(); !received.empty()) {
      std::ofstream f(run.dir / "galvo_list.txt");
      f << "# the list as " << machine.scanner->info().model << " received it\n" << received;
      if (!f.good()) log->warn("cannot write {}", (run.dir / "galvo_list.txt").string());
    }
    if (!ran.ok()) return PhaseFailure(ran, "marking: ");
  }
  log->info("mark: done");
  return before;
}

// 5. Look at what was marked.
Status Verify(MarkRun& run, const geometry::SurfaceModel& surface,
              const std::vector<std::vector<pattern::Segment2>>& placed_items,
              const std::vector<pattern::ListCommand>& list, const SideBefore& before) {
  const MarkJobSpec& mark = run.mark;
  if (Cancelled(run.options)) return Status(StatusCode::kCancelled, "cancelled");
  PhaseProgress verifying(run.options, "verify", "steps", 1);
  double side_exposure_us = before.exposure_us;
  auto after = GrabSideView(run.up.machine, mark.verify, &side_exposure_us);
  if (!after.ok()) return PhaseFailure(after.status(), "side camera after marking: ");
  MarkDesign design;
  for (size_t i = 0; i < mark.items.size(); ++i) {
    const ItemSpec& it = mark.items[i];
    ItemDesign d;
    d.placed = placed_items[i];
    d.spacing_mm = it.hatch_angles_deg.empty() ? 0.0 : it.hatch_spacing_mm;
    d.hatch_angle_deg =
        it.hatch_angles_deg.empty() ? 0.0 : it.hatch_angles_deg.front() + it.placement.rotation_deg;
    design.items.push_back(std::move(d));
  }
  for (const pattern::ListCommand& c : list) {
    if (c.op == pattern::ListOp::kMarkAbs) design.mark_points.push_back(c.p);
  }
  const Status verified =
      VerifyMarks(run.up.machine, run.up.calibration, surface, design, mark.verify, before.frame,
                  *after, run.options.out_dir, &run.report);
  if (!verified.ok()) return PhaseFailure(verified, "verification: ");
  verifying.Update(1);
  return Status::Ok();
}

}  // namespace

Status CheckMarkJob(const LoadedJob& job) {
  ScanJobSpec spec;
  MarkJobSpec mark;
  hw::MachineConfig machine_config;
  return ReadScanJob(job, &spec, &machine_config,
                     [&](ConfigReader& r) { ReadMarkSections(r, job.folder, &mark); });
}

Result<Report> RunMarkJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ScanJobSpec spec;
  MarkJobSpec mark;
  hw::MachineConfig machine_config;
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, &spec, &machine_config, [&](ConfigReader& r) {
    ReadMarkSections(r, job.folder, &mark);
  }));
  // The patterns are read before the machine moves: a bad pattern file fails
  // now.
  INSITU_ASSIGN_OR_RETURN(Patterns patterns, LoadPatterns(mark, job.path));
  INSITU_ASSIGN_OR_RETURN(pattern::FieldCorrection correction, LoadCorrection(mark, job.path));
  INSITU_ASSIGN_OR_RETURN(ScanMachine up, BringUp(job, spec, machine_config, options));
  const bool bypassed_measured_head = UseCalibratedHead(up.calibration, &mark, &correction);
  INSITU_RETURN_IF_ERROR(FitHeadLimits(up.machine.scanner->info(), job.path, &mark));

  INSITU_ASSIGN_OR_RETURN(Report report,
                          StartReport(job.kind, options.out_dir, up.machine.warnings));
  if (bypassed_measured_head) {
    report.warnings.push_back(
        "head.correction / head.model_extension is used in place of the head the calibration "
        "measured (field_calibration): marks follow that table, not the measured head");
  }
  // Once the cell is up, a phase's failure ends the job as a device error with its report.
  auto finish = [&](const Status& failure) {
    return FinishReport(report, failure.ok(), failure.message(), wall_start, options.out_dir,
                        StatusCode::kDeviceError);
  };
  MarkRun run{spec, mark, options, up, report, options.out_dir};

  auto scanned = ScanPart(run);
  if (!scanned.ok()) return finish(scanned.status());
  auto surface = Place(run, scanned->cloud, &patterns.placed_items);
  if (!surface.ok()) return finish(surface.status());
  pattern::MarkPlanReport plan;
  auto list = Plan(run, *surface, patterns.placed_items, patterns.paths, &plan);
  if (!list.ok()) return finish(list.status());
  if (const Status emitted = Emit(run, *list, correction); !emitted.ok()) return finish(emitted);
  auto before = Mark(run, *list, plan, correction);
  if (!before.ok()) return finish(before.status());
  if (mark.verify.enabled) {
    const Status verified = Verify(run, *surface, patterns.placed_items, *list, *before);
    if (!verified.ok()) return finish(verified);
  }
  return finish(Status::Ok());
}

}  // namespace insitu::job
