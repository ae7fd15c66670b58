#include "job/inspect_grooves.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "insitu/core/log.h"
#include "insitu/core/robust.h"
#include "insitu/geometry/cloud.h"
#include "insitu/geometry/surface.h"
#include "insitu/inspect/contours.h"
#include "insitu/inspect/groove.h"
#include "insitu/job/plot.h"
#include "insitu/pattern/mark_plan.h"
#include "insitu/pattern/vector.h"
#include "job/cell.h"
#include "job/format.h"
#include "job/groove_cell.h"
#include "job/head_list.h"
#include "job/output_path.h"
#include "job/progress.h"
#include "job/scan_job.h"

namespace insitu::job {
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = M_PI / 180.0;

struct GrooveJobSpec {
  std::string design_file;  // resolved
  // Arcs flattened to within this: 1 um, under the profiler's noise (the design's own chords
  // would read as local error).
  double design_tolerance_mm = 0.001;
  // Where the panel's tooling holes are in the galvo frame: `fixture` takes the fixture's pins
  // (nominal), `measured` finds the holes in a scan of the part.
  std::string registration = "fixture";
  Eigen::Vector2d pin_a_mm{-50.0, -40.0}, pin_b_mm{50.0, -40.0};  // galvo frame
  double surface_z_mm = 2.31;      // the panel's top at the fixture, galvo z (nominal)
  double hole_diameter_mm = 6.0;
  bool engrave = true;
  int passes = 1;
  pattern::MarkSettings laser;
  geometry::SurfaceOptions surface;
  ProfilerSpec profiler;
  bool inspect = true;
  double profile_spacing_mm = 0.2;
  inspect::GrooveOptions groove;
  double alpha_per_mm = 0.0;  // 0: chosen from the first alpha_sample profiles
  int alpha_sample = 20;
  double cluster_tolerance_mm = 5.0;  // seed 002: 5 mm
  double match_distance_mm = 5.0;
};

void ReadGrooveSections(ConfigReader& r, const std::string& folder, GrooveJobSpec* s) {
  ConfigReader& d = r.Section("design");
  d.Require("file");
  std::string file;
  d.Read("file", &file);
  s->design_file = ResolvePath(folder, file);
  d.Read("tolerance_mm", &s->design_tolerance_mm);
  if (d.ok() && !(s->design_tolerance_mm > 0 && s->design_tolerance_mm < 1))
    d.Fail("tolerance_mm", "must be in (0, 1)");

  ConfigReader& p = r.Section("placement");
  p.ReadEnum("registration", &s->registration, {"fixture", "measured"});
  p.ReadArray("pin_a_mm", s->pin_a_mm.data(), 2);
  p.ReadArray("pin_b_mm", s->pin_b_mm.data(), 2);
  p.Read("surface_z_mm", &s->surface_z_mm);
  p.Read("hole_diameter_mm", &s->hole_diameter_mm);
  if (p.ok() && !((s->pin_b_mm - s->pin_a_mm).norm() > 2 * s->hole_diameter_mm))
    p.Fail("pin_b_mm", "must lie more than two hole diameters from pin_a_mm");
  if (p.ok() && !(s->hole_diameter_mm > 0.5 && s->hole_diameter_mm < 50))
    p.Fail("hole_diameter_mm", "must be in (0.5, 50)");

  ConfigReader& e = r.Section("engrave");
  e.Read("enabled", &s->engrave);
  e.Read("passes", &s->passes);
  e.Read("defocus_mm", &s->laser.focus_offset_mm);
  e.Read("power", &s->laser.laser_power);
  e.Read("frequency_khz", &s->laser.laser_frequency_khz);
  e.Read("mark_speed_mm_per_s", &s->laser.mark_speed_mm_per_s);
  e.Read("jump_speed_mm_per_s", &s->laser.jump_speed_mm_per_s);
  e.Read("laser_on_delay_us", &s->laser.laser_on_delay_us);
  e.Read("laser_off_delay_us", &s->laser.laser_off_delay_us);
  e.Read("jump_delay_us", &s->laser.jump_delay_us);
  e.Read("mark_delay_us", &s->laser.mark_delay_us);
  e.Read("max_step_mm", &s->laser.max_step_mm);
  if (e.ok() && (s->passes < 1 || s->passes > 100)) e.Fail("passes", "must be in [1, 100]");
  if (e.ok()) e.FailFromValidate(s->laser.Validate());

  ConfigReader& su = r.Section("surface");
  su.Read("radius_mm", &s->surface.radius_mm);
  su.Read("min_points", &s->surface.min_points);
  su.Read("max_residual_mm", &s->surface.max_residual_mm);

  ReadProfilerSection(r.Section("profiler"), folder, &s->profiler);

  ConfigReader& in = r.Section("inspect");
  in.Read("enabled", &s->inspect);
  in.Read("profile_spacing_mm", &s->profile_spacing_mm);
  in.Read("expected_width_mm", &s->groove.expected_width_mm);
  in.Read("window_mm", &s->groove.window_mm);
  in.Read("outlier_sigmas", &s->groove.outlier_sigmas);
  in.Read("alpha_per_mm", &s->alpha_per_mm);
  in.Read("alpha_sample", &s->alpha_sample);
  in.Read("cluster_tolerance_mm", &s->cluster_tolerance_mm);
  in.Read("match_distance_mm", &s->match_distance_mm);
  if (in.ok() && !(s->profile_spacing_mm >= 0.005 && s->profile_spacing_mm <= 50))
    in.Fail("profile_spacing_mm", "must be in [0.005, 50]");
  if (in.ok() && !(s->alpha_per_mm >= 0)) in.Fail("alpha_per_mm", "must be >= 0 (0: from data)");
  if (in.ok() && (s->alpha_sample < 3 || s->alpha_sample > 1000))
    in.Fail("alpha_sample", "must be in [3, 1000]");
  if (in.ok() && !(s->cluster_tolerance_mm > 0)) in.Fail("cluster_tolerance_mm", "must be > 0");
  if (in.ok() && !(s->match_distance_mm > 0)) in.Fail("match_distance_mm", "must be > 0");
  if (in.ok()) in.FailFromValidate(s->groove.Validate());
}

// The design's closed contours, in the workpiece frame (mm). Errors: the file's own, or a design
// with no closed contour (grooves are inspected along closed contours).
Result<std::vector<pattern::Polyline>> LoadContours(const GrooveJobSpec& s, int* open_paths) {
  Result<pattern::VectorPattern> vec =
      pattern::LoadVectorFile(s.design_file, s.design_tolerance_mm);
  if (!vec.ok()) return vec.status();
  std::vector<pattern::Polyline> closed;
  *open_paths = 0;
  for (const pattern::Polyline& p : vec->paths) {
    if (p.closed && p.points.size() >= 3) {
      closed.push_back(p);
    } else {
      ++*open_paths;
    }
  }
  if (closed.empty()) {
    return InvalidArgument(s.design_file + ": the design has no closed contour (" +
                           std::to_string(*open_paths) +
                           " open paths): grooves are inspected along closed contours");
  }
  return closed;
}

// Points every `spacing` along a closed polyline, each with its unit tangent.
struct Station {
  Eigen::Vector2d point, tangent;
  double s_mm = 0.0;  // arc length from the contour's first point
};
std::vector<Station> Stations(const pattern::Polyline& c, double spacing) {
  std::vector<Eigen::Vector2d> v = c.points;
  if ((v.front() - v.back()).norm() > 1e-9) v.push_back(v.front());
  double length = 0;
  for (size_t i = 1; i < v.size(); ++i) length += (v[i] - v[i - 1]).norm();
  const int n = std::max(3, static_cast<int>(std::round(length / spacing)));
  const double step = length / n;
  std::vector<Station> out;
  size_t seg = 1;
  double start = 0;  // arc length at v[seg - 1]
  for (int k = 0; k < n; ++k) {
    const double s = (k + 0.5) * step;
    while (seg + 1 < v.size() && start + (v[seg] - v[seg - 1]).norm() < s) {
      start += (v[seg] - v[seg - 1]).norm();
      ++seg;
    }
    const Eigen::Vector2d d = v[seg] - v[seg - 1];
    const double len = d.norm();
    if (!(len > 0)) continue;
    out.push_back({v[seg - 1] + d * std::clamp((s - start) / len, 0.0, 1.0), d / len, s});
  }
  return out;
}

// The panel's tooling holes in a scan's cloud (galvo frame), about where the pins say: per scan
// line through a hole, the gap in the panel's top the hole leaves, its rims half a sample
// beyond the last top points either side; a circle through the rims. Errors name the hole.
Result<PanelFrame> HolesInCloud(const geometry::Cloud& cloud, const GrooveJobSpec& s,
                                std::vector<std::string>* notes) {
  const double r = 0.5 * s.hole_diameter_mm;
  Eigen::Vector2d centre[2];
  double tops[2] = {0, 0};
  for (int h = 0; h < 2; ++h) {
    const char* name = h == 0 ? "tooling hole A" : "tooling hole B";
    const Eigen::Vector2d pin = h == 0 ? s.pin_a_mm : s.pin_b_mm;
    // The top around the hole, from the ring 1-2 mm beyond its rim (wherever the fixture put
    // it within half a millimetre).
    std::vector<double> ring;
    for (const geometry::CloudPoint& p : cloud) {
      const double d = (p.point_in_galvo.head<2>().cast<double>() - pin).norm();
      if (d > r + 1.0 && d < r + 2.0) ring.push_back(p.point_in_galvo.z());
    }
    if (ring.size() < 20) {
      return FailedPrecondition(std::string(name) + Fmt(": the scan saw %.0f points around it at "
                                                        "(%.2f, ...): scan over the pins",
                                                        static_cast<double>(ring.size()), pin.x()));
    }
    const double top = MedianInPlace(ring), threshold = top - 0.2;
    std::map<int, std::vector<Eigen::Vector3d>> lines;
    for (const geometry::CloudPoint& p : cloud) {
      const Eigen::Vector2d q = p.point_in_galvo.head<2>().cast<double>();
      if ((q - pin).norm() < r + 2.0) lines[p.line].push_back(p.point_in_galvo.cast<double>());
    }
    std::vector<Eigen::Vector2d> rim;
    for (auto& [line, pts] : lines) {
      std::vector<Eigen::Vector3d> on_top;
      for (const Eigen::Vector3d& q : pts) {
        if (q.z() > threshold) on_top.push_back(q);
      }
      if (on_top.size() < 6) continue;
      std::sort(on_top.begin(), on_top.end(),
                [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a.y() < b.y(); });
      // The sample spacing along the line, and its widest gap: the hole.
      std::vector<double> gaps;
      size_t widest = 0;
      for (size_t i = 1; i < on_top.size(); ++i) {
        gaps.push_back(on_top[i].y() - on_top[i - 1].y());
        if (gaps.back() > gaps[widest]) widest = i - 1;
      }
      const double spacing = Median(gaps);
      // A chord shorter than a fifth of the diameter grazes the rim: its ends say little. A gap
      // that does not straddle the pin, or is longer than the hole, is no chord of it (points
      // the stripe's extraction left out, the scan's end).
      const Eigen::Vector3d& a = on_top[widest];
      const Eigen::Vector3d& b = on_top[widest + 1];
      if (!(gaps[widest] > std::max(5.0 * spacing, 0.4 * r))) continue;
      if (!(gaps[widest] < 2.0 * r + 0.5 && a.y() < pin.y() + 0.5 * r &&
            b.y() > pin.y() - 0.5 * r)) {
        continue;
      }
      rim.push_back({a.x(), a.y() + 0.5 * spacing});
      rim.push_back({b.x(), b.y() - 0.5 * spacing});
    }
    if (rim.size() < 6) {
      return FailedPrecondition(std::string(name) + ": " + std::to_string(rim.size() / 2) +
                                " scan lines cross it (at least 3 needed): scan across the pins "
                                "with lines closer than a third of the hole's diameter");
    }
    auto circle = FitCircle2(rim);
    if (!circle.ok()) return circle.status().Prefixed(name);
    {
      // Rim points far off the circle (a rim the stripe's extraction blurred): left out once,
      // beyond 4 robust deviations of the others.
      std::vector<double> off;
      for (const auto& q : rim) off.push_back(std::abs((q - circle->centre).norm() - circle->radius));
      const double limit = 4.0 * kMadToSigma * Median(off) + 1e-3;
      std::vector<Eigen::Vector2d> kept;
      for (size_t i = 0; i < rim.size(); ++i) {
        if (off[i] <= limit) kept.push_back(rim[i]);
      }
      if (kept.size() >= 6 && kept.size() < rim.size()) {
        auto refit = FitCircle2(kept);
        if (refit.ok()) circle = refit;
      }
    }
    // A circle far from the drawing's hole is another feature, or rims misread: refused by
    // name. The side camera's chords come out short by up to a few samples (~0.3 mm on 6).
    if (std::abs(2.0 * circle->radius - s.hole_diameter_mm) > 0.6 || circle->rms > 0.15) {
      return FailedPrecondition(std::string(name) +
                                Fmt(": the scan's rims make a %.3f mm circle (rms %.0f um), not the "
                                    "drawing's %.2f mm hole",
                                    2.0 * circle->radius, 1e3 * circle->rms, s.hole_diameter_mm));
    }
    centre[h] = circle->centre;
    tops[h] = top;
    notes->push_back(std::string(name) +
                     Fmt(" at (%.4f, %.4f) mm in the galvo frame, diameter %.3f mm", centre[h].x(),
                         centre[h].y(), 2 * circle->radius) +
                     Fmt(" (%.0f chords, rim rms %.1f um)", rim.size() / 2.0, 1e3 * circle->rms));
  }
  return PanelFrame::FromHoles(centre[0], centre[1], (s.pin_b_mm - s.pin_a_mm).norm(),
                               0.5 * (tops[0] + tops[1]));
}

// The fixture's nominal top as a surface (a plane at surface_z_mm over the design's extent):
// what marking "by fixture coordinates" assumes the part is.
Result<geometry::SurfaceModel> NominalSurface(const std::vector<pattern::Segment2>& placed,
                                              double z_mm) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& sg : placed) {
    lo = lo.cwiseMin(sg.a.cwiseMin(sg.b));
    hi = hi.cwiseMax(sg.a.cwiseMax(sg.b));
  }
  geometry::Cloud grid;
  for (double y = lo.y() - 2.0; y <= hi.y() + 2.0; y += 0.5) {
    for (double x = lo.x() - 2.0; x <= hi.x() + 2.0; x += 0.5) {
      geometry::CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y),
                                         static_cast<float>(z_mm));
      grid.push_back(p);
    }
  }
  geometry::SurfaceOptions o;
  o.radius_mm = 1.0;
  return geometry::SurfaceModel::Build(grid, o);
}

// One profile's record.
struct ProfileRecord {
  int contour = -1;
  double s_mm = 0.0;                 // arc length along the design contour
  Eigen::Vector2d design_mm;         // the station, workpiece frame
  inspect::Profile profile;          // cut about the expected groove
  double expected_x_mm = 0.0;       // where the design says the groove is, sensor frame
  inspect::Groove groove;
  Eigen::Vector2d centre_mm = Eigen::Vector2d::Constant(NAN);  // workpiece frame
  hw::AxisPose axes;
};

// Colour for a value in [0, 1]: blue - green - yellow - red.
int Heat(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = std::clamp(2.0 * t, 0.0, 1.0), g = std::clamp(2.0 - 2.0 * t, 0.0, 1.0) *
                                                           std::clamp(2.0 * t + 0.3, 0.0, 1.0);
  const double b = std::clamp(1.0 - 2.0 * t, 0.0, 1.0);
  return (static_cast<int>(255 * r) << 16) | (static_cast<int>(255 * g) << 8) |
         static_cast<int>(255 * b);
}

}  // namespace

Status CheckInspectGroovesJob(const LoadedJob& job) {
  ScanJobSpec spec;
  GrooveJobSpec g;
  hw::MachineConfig config;
  return ReadScanJob(job, &spec, &config,
                     [&](ConfigReader& r) { ReadGrooveSections(r, job.folder, &g); });
}

Result<Report> RunInspectGroovesJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ScanJobSpec spec;
  GrooveJobSpec g;
  hw::MachineConfig config;
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, &spec, &config, [&](ConfigReader& r) {
    ReadGrooveSections(r, job.folder, &g);
  }));
  // Everything read before the machine moves: a bad design, block or mount file fails now.
  int open_paths = 0;
  auto loaded = LoadContours(g, &open_paths);
  if (!loaded.ok()) return loaded.status().Prefixed(job.path + ": design");
  const std::vector<pattern::Polyline> contours = std::move(*loaded);
  std::optional<inspect::SensorMount> mount;
  std::optional<inspect::CalibrationBlock> block;
  if (g.inspect) {
    if (!g.profiler.mount_file.empty()) {
      auto m = LoadMount(g.profiler.mount_file);
      if (!m.ok()) return m.status().Prefixed(job.path + ": profiler.mount_file");
      mount = *m;
    } else {
      auto b = BlockOf(g.profiler);
      if (!b.ok()) return b.status().Prefixed(job.path + ": profiler.block");
      block = std::move(*b);
    }
  }
  INSITU_ASSIGN_OR_RETURN(ScanMachine up, BringUp(job, spec, config, options));
  hw::Machine& m = up.machine;
  if (g.inspect) {
    INSITU_RETURN_IF_ERROR(m.Require({hw::Role::kAxis, hw::Role::kProfiler},
                                     job.path + ": inspect (inspect.enabled: false engraves "
                                                "only)"));
  }

  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir, m.warnings));
  const fs::path dir(options.out_dir);
  auto log = Logger("job");
  auto finish = [&](bool ok, const std::string& error) {
    return FinishReport(report, ok, error, wall_start, options.out_dir, StatusCode::kDeviceError);
  };
  const auto cancelled = [&] { return options.cancel != nullptr && options.cancel->load(); };
  report.metrics["contours_expected"] = static_cast<double>(contours.size());
  if (open_paths > 0) {
    report.warnings.push_back(std::to_string(open_paths) +
                              " open paths of the design are not inspected (contours are closed)");
  }

  // 1. Engrave: the design placed on the panel by its tooling holes, where the fixture's pins
  // say they are or where a scan of the part finds them.
  if (g.engrave) {
    PanelFrame galvo_frame;
    std::optional<geometry::SurfaceModel> surface;
    if (g.registration == "measured") {
      PhaseProgress progress(options, "scan", "lines", spec.scan.line_count());
      auto scanned = RunScan(
          m, spec.scan, spec.extraction, up.calibration,
          [&](int done, int) { progress.Update(done); }, options.cancel);
      if (!scanned.ok()) return finish(false, "scan: " + scanned.status().ToString());
      ReportScanLight(scanned->stats, &report);
      report.metrics["points"] = static_cast<double>(scanned->cloud.size());
      const Status saved = geometry::SaveCloudPly(scanned->cloud, (dir / "cloud.ply").string());
      if (!saved.ok()) return finish(false, saved.ToString());
      report.artifacts["cloud"] = "cloud.ply";
      auto frame = HolesInCloud(scanned->cloud, g, &report.warnings);
      if (!frame.ok()) return finish(false, "registration: " + frame.status().ToString());
      galvo_frame = *frame;
      auto built = geometry::SurfaceModel::Build(scanned->cloud, g.surface);
      if (!built.ok()) return finish(false, "surface: " + built.status().ToString());
      surface = std::move(*built);
      const Eigen::Vector2d d = galvo_frame.origin_mm - g.pin_a_mm;
      report.metrics["registration_offset_x_mm"] = d.x();
      report.metrics["registration_offset_y_mm"] = d.y();
      report.metrics["registration_rotation_deg"] =
          galvo_frame.rotation_deg() -
          std::atan2((g.pin_b_mm - g.pin_a_mm).y(), (g.pin_b_mm - g.pin_a_mm).x()) / kDeg;
    } else {
      galvo_frame = PanelFrame::FromHoles(g.pin_a_mm, g.pin_b_mm, (g.pin_b_mm - g.pin_a_mm).norm(),
                                          g.surface_z_mm);
    }
    std::vector<pattern::Segment2> placed;
    for (const pattern::Polyline& c : contours) {
      for (size_t i = 0; i < c.points.size(); ++i) {
        const Eigen::Vector2d a = c.points[i], b = c.points[(i + 1) % c.points.size()];
        if ((a - b).norm() > 0) {
          placed.push_back({galvo_frame.ToMachine(a), galvo_frame.ToMachine(b)});
        }
      }
    }
    if (!surface) {
      auto nominal = NominalSurface(placed, g.surface_z_mm);
      if (!nominal.ok()) return finish(false, "surface: " + nominal.status().ToString());
      surface = std::move(*nominal);
    }
    std::vector<pattern::Segment2> passes;
    for (int k = 0; k < g.passes; ++k) passes.insert(passes.end(), placed.begin(), placed.end());
    // The marking beam's slant from the head's model (the calibration's: design, or as the
    // field calibration measured it), for the defocused beam to meet the film on the contour.
    g.laser.beam_up = [head = up.calibration.head.model](const Eigen::Vector3d& cmd) {
      optics::ChiefRay ray;
      return head.Land(cmd, {}, &ray) ? ray.up : Eigen::Vector3d(Eigen::Vector3d::UnitZ());
    };
    pattern::MarkPlanReport plan;
    auto list = pattern::PlanMarking(passes, *surface, g.laser, &plan);
    if (!list.ok()) return finish(false, "engraving plan: " + list.status().ToString());
    if (plan.points_without_surface > 0) {
      report.warnings.push_back(std::to_string(plan.points_without_surface) +
                                " design points have no measured surface and are not engraved");
    }
    report.metrics["engraved_length_mm"] = plan.marked_length_mm;
    const pattern::FieldCorrection correction = MeasuredHeadCorrection(up.calibration);
    pattern::HeadFormat head;
    const hw::ScannerInfo info = m.scanner->info();
    head.field_half_size_mm = info.field_half_size_mm;
    head.focus_half_range_mm = info.focus_range_mm;
    auto emitted = pattern::Emit(*list, head, correction);
    if (!emitted.ok()) return finish(false, "galvo list: " + emitted.status().ToString());
    {
      std::ofstream f(dir / "galvo_list.txt");
      f << pattern::FormatEmitted(*emitted, head);
    }
    report.artifacts["galvo_list"] = "galvo_list.txt";
    if (cancelled()) return finish(false, "cancelled");
    const Status armed = m.scanner->Arm();
    if (!armed.ok()) return finish(false, "arm: " + armed.ToString());
    {
      ArmGuard guard{m.scanner.get()};
      const double list_ms = std::round(pattern::ListDuration(*list) * 1e3);
      PhaseProgress marking(options, "engrave", "ms", list_ms);
      hw::ListControl control;
      control.abort = options.cancel;
      control.progress = [&](double f) { marking.Update(std::round(f * list_ms)); };
      log->info("inspect_grooves: engraving {:.0f} mm of contour, {} passes",
                plan.marked_length_mm / g.passes, g.passes);
      const Status ran = m.scanner->ExecuteList(ToHeadList(*list, correction), control);
      if (!ran.ok()) return finish(false, "engraving: " + ran.ToString());
    }
  }
  if (!g.inspect) return finish(true, "");

  // 2. The profiler's mounting: the calibrated file, or calibrated now on the block.
  if (!mount) {
    PhaseProgress progress(options, "profiler calibration", "steps", 1);
    auto cal = CalibrateMountOnBlock(*m.axis, *m.profiler, *block, MountFromPose(g.profiler.drawing),
                                     g.profiler.block_scan, options.cancel);
    if (!cal.ok()) return finish(false, "profiler calibration: " + cal.status().ToString());
    mount = cal->mount;
    const Status saved = SaveMount(*cal, m.profiler->info(), (dir / "mount.yaml").string());
    if (!saved.ok()) return finish(false, saved.ToString());
    report.artifacts["mount"] = "mount.yaml";
    report.metrics["mount_fit_rms_um"] = 1e3 * cal->rms_mm;
    progress.Update(1);
  }

  // 3. The workpiece frame: the panel's tooling holes as the profiler measures them.
  auto datums = MeasureDatums(*m.axis, *m.profiler, *mount, g.profiler.datums, options.cancel);
  if (!datums.ok()) return finish(false, "datums: " + datums.status().ToString());
  const PanelFrame& frame = datums->frame;
  report.metrics["datum_rim_rms_um"] = 1e3 * datums->rim_rms_mm;
  report.metrics["datum_hole_distance_mm"] = (datums->hole_mm[1] - datums->hole_mm[0]).norm();

  // alpha from data (seed 002 Fig. 4), then every profile's groove, saved to grooves.csv with the
  // reason of every profile without one: run once the profiles are in, or on the profiles taken
  // when the scan ends early. Errors: no profile holds a groove (after saving).
  double alpha = g.alpha_per_mm;
  int fitted = 0;
  double width_sum = 0, depth_sum = 0, rms_sum = 0;
  std::vector<ProfileRecord> records;
  const auto fit_and_save = [&]() -> Status {
    bool chosen = alpha > 0;
    if (!chosen && !records.empty()) {
      std::vector<inspect::Profile> sample;
      const size_t stride = std::max<size_t>(1, records.size() / g.alpha_sample);
      for (size_t k = 0; k < records.size() && static_cast<int>(sample.size()) < g.alpha_sample;
           k += stride) {
        sample.push_back(records[k].profile);
      }
      inspect::GrooveOptions o = g.groove;
      o.expected_x_mm = NAN;  // each profile of the sample is already cut about its groove
      auto choice = inspect::ChooseAlpha(sample, o);
      if (choice.ok()) {
        chosen = true;
        alpha = choice->alpha_per_mm;
        std::vector<double> a, rms;
        for (size_t k = 0; k < choice->candidates.size(); ++k) {
          a.push_back(choice->candidates[k]);
          rms.push_back(1e3 * choice->rms_mm[k]);
        }
        PlotSpec ps;
        ps.title = Fmt("Template sharpness from data (seed 002 Fig. 4): alpha %.0f /mm", alpha);
        ps.x_label = "alpha (1/mm)";
        ps.y_label = "rms residual over the sample (um)";
        ps.series.push_back({"candidates", a, rms, PlotColor(0)});
        if (SavePlotPng(ps, (dir / "alpha.png").string()).ok()) {
          report.artifacts["alpha_plot"] = "alpha.png";
        }
      }
    }
    // Without a groove at any candidate, each profile's reason at seed 002's 20 /mm.
    inspect::GrooveOptions fit = g.groove;
    fit.alpha_per_mm = chosen ? alpha : 20.0;
    if (chosen) report.metrics["groove_alpha_per_mm"] = alpha;
    std::map<std::string, int> reasons;
    fitted = 0;
    width_sum = depth_sum = rms_sum = 0;
    for (ProfileRecord& rec : records) {
      fit.expected_x_mm = rec.expected_x_mm;
      rec.groove = inspect::FitGroove(rec.profile, fit);
      if (!rec.groove.ok) {
        // The reason's kind, without its numbers, counted.
        std::string kind = rec.groove.why.substr(0, rec.groove.why.find_first_of("0123456789("));
        ++reasons[kind];
        continue;
      }
      const Eigen::Vector3d q =
          ProfilePointInMachine(rec.axes, *mount, rec.groove.x_mm, rec.groove.z_mm);
      rec.centre_mm = frame.ToWorkpiece(q.head<2>());
      ++fitted;
      width_sum += rec.groove.width_mm;
      depth_sum += rec.groove.depth_mm;
      rms_sum += rec.groove.rms_mm;
    }
    report.metrics["profiles"] = static_cast<double>(records.size());
    report.metrics["profiles_invalid"] = static_cast<double>(records.size() - fitted);
    for (const auto& [why, count] : reasons) {
      report.warnings.push_back(std::to_string(count) + " profiles without a groove: " + why);
    }
    if (fitted > 0) {
      report.metrics["groove_width_um_mean"] = 1e3 * width_sum / fitted;
      report.metrics["groove_depth_um_mean"] = 1e3 * depth_sum / fitted;
      report.metrics["groove_fit_rms_um"] = 1e3 * rms_sum / fitted;
    }
    {
      std::ofstream csv(dir / "grooves.csv");
      csv << "contour,s_mm,design_x_mm,design_y_mm,x_mm,y_mm,width_um,depth_um,fit_rms_um,why\n";
      csv.precision(8);
      for (const ProfileRecord& r : records) {
        csv << r.contour << ',' << r.s_mm << ',' << r.design_mm.x() << ',' << r.design_mm.y() << ',';
        if (r.groove.ok) {
          csv << r.centre_mm.x() << ',' << r.centre_mm.y() << ',' << 1e3 * r.groove.width_mm << ','
              << 1e3 * r.groove.depth_mm << ',' << 1e3 * r.groove.rms_mm << ",\n";
        } else {
          std::string why = r.groove.why;
          std::replace(why.begin(), why.end(), ',', ';');
          csv << ",,,,," << why << '\n';
        }
      }
      if (csv.good()) report.artifacts["grooves"] = "grooves.csv";
    }
    if (fitted == 0) {
      return FailedPrecondition(
          "no profile holds a groove (" + std::to_string(records.size()) + " profiles" +
          (records.empty() ? std::string() : "; the first: " + records.front().groove.why) +
          "): is anything engraved where the design says?");
    }
    return Status::Ok();
  };
  // A scan that ends early: the profiles taken fitted and saved, then the reason.
  const auto stop = [&](const std::string& why) {
    report.metrics["profiles"] = static_cast<double>(records.size());
    std::string kept;
    if (!records.empty()) {
      const Status saved = fit_and_save();
      kept = " (the " + std::to_string(records.size()) + " profiles taken are in grooves.csv" +
             (saved.ok() ? "" : "; " + saved.ToString()) + ")";
    }
    return finish(false, why + kept);
  };

  // 4. Profiles across the grooves, square to the design's contours (seed 002: the scan path
  // from the engraving's own path), each cut to the window about where the groove should be.
  {
    std::vector<std::pair<int, Station>> plan;
    for (size_t c = 0; c < contours.size(); ++c) {
      for (const Station& st : Stations(contours[c], g.profile_spacing_mm)) {
        plan.push_back({static_cast<int>(c), st});
      }
    }
    PhaseProgress progress(options, "profiles", "profiles", static_cast<double>(plan.size()));
    const hw::ProfilerInfo info = m.profiler->info();
    g.groove.z_resolution_mm = std::max(info.z_resolution_mm, 1e-5);
    if (info.z_max_mm > info.z_min_mm) {  // a sensor that states its measuring range
      g.groove.z_min_mm = info.z_min_mm;
      g.groove.z_max_mm = info.z_max_mm;
    }
    for (size_t k = 0; k < plan.size(); ++k) {
      if (cancelled()) return stop("cancelled");
      const auto& [c, st] = plan[k];
      ProfileRecord rec;
      rec.contour = c;
      rec.s_mm = st.s_mm;
      rec.design_mm = st.point;
      const Eigen::Vector2d at = frame.ToMachine(st.point);
      const Eigen::Vector2d across = frame.ToMachine(st.point + Eigen::Vector2d(-st.tangent.y(), st.tangent.x())) - at;
      const Eigen::Vector3d target(at.x(), at.y(), frame.top_z_mm);
      const Status moved = m.axis->MoveTo(AxesForSensorAt(*mount, target, across));
      if (!moved.ok()) return stop("profile " + std::to_string(k) + ": move: " + moved.ToString());
      auto axes = m.axis->Position();
      if (!axes.ok()) return stop("axis position: " + axes.status().ToString());
      rec.axes = *axes;
      auto shot = m.profiler->Grab();
      if (!shot.ok()) {
        return stop("profile " + std::to_string(k) + " of " + std::to_string(plan.size()) + ": " +
                    shot.status().ToString());
      }
      const double expected = SensorXOf(*axes, *mount, target);
      rec.profile.dx_mm = shot->x_spacing_mm;
      rec.profile.stamp = shot->encoder;
      // Kept: the window about the expected groove and as much again for the surface.
      const double keep = 2.0 * g.groove.window_mm + g.groove.expected_width_mm;
      const int first = std::max(0, static_cast<int>(std::floor((expected - keep - shot->x_start_mm) /
                                                                 shot->x_spacing_mm)));
      const int end = std::min(static_cast<int>(shot->z_mm.size()),
                               static_cast<int>(std::ceil((expected + keep - shot->x_start_mm) /
                                                          shot->x_spacing_mm)) + 1);
      rec.profile.x_start_mm = shot->x_start_mm + first * shot->x_spacing_mm;
      if (end > first) rec.profile.z_mm.assign(shot->z_mm.begin() + first, shot->z_mm.begin() + end);
      rec.expected_x_mm = expected;
      records.push_back(std::move(rec));
      progress.Update(static_cast<double>(k + 1));
    }
  }
  {
    const Status fitted_all = fit_and_save();
    if (!fitted_all.ok()) return finish(false, fitted_all.ToString());
  }


  // 6. Contours (seed 002 section 2.2): the centres clustered, matched to the design's contours
  // by centroid, compared point by point.
  inspect::Points2 centres;
  for (const ProfileRecord& r : records) {
    if (r.groove.ok) centres.push_back(r.centre_mm);
  }
  const auto clusters = inspect::ClusterPoints(centres, g.cluster_tolerance_mm);
  std::vector<inspect::Points2> measured(clusters.size()), design(contours.size());
  for (size_t k = 0; k < clusters.size(); ++k) {
    for (int i : clusters[k]) measured[k].push_back(centres[i]);
  }
  for (size_t c = 0; c < contours.size(); ++c) design[c] = contours[c].points;
  const auto matches = inspect::MatchContours(design, measured, g.match_distance_mm);
  report.metrics["contours_matched"] = static_cast<double>(matches.size());
  report.metrics["contour_clusters"] = static_cast<double>(clusters.size());
  Eigen::Vector2d offset_sum = Eigen::Vector2d::Zero();
  double scale_sum = 0, stretch_sum = 0, local_max = 0;
  std::ostringstream per;
  per << "[";
  PlotSpec map;
  map.title = "Measured groove centres, coloured by local error (blue 0 .. red max)";
  map.x_label = "x (mm, workpiece frame)";
  map.y_label = "y (mm)";
  PlotSpec split;
  split.title = "Contour error split: offset |E|, bending (scale, stretch) and local, per contour";
  split.x_label = "contour";
  split.y_label = "um";
  PlotSeries off_s{"offset |E|", {}, {}, PlotColor(0)},
      scale_s{"bending: (|scale| + stretch) x half size", {}, {}, PlotColor(1)},
      local_s{"local rms", {}, {}, PlotColor(2)}, local_m{"local max", {}, {}, PlotColor(3)};
  std::vector<inspect::ContourError> errors;
  for (const inspect::ContourMatch& match : matches) {
    auto e = inspect::CompareContour(design[match.design], measured[match.measured],
                                     /*closed=*/true);
    if (!e.ok()) return finish(false, "contour " + std::to_string(match.design) + ": " + e.status().ToString());
    offset_sum += e->offset_mm;
    scale_sum += e->scale_pct;
    stretch_sum += e->stretch_pct;
    local_max = std::max(local_max, e->local_max_mm);
    per << (errors.empty() ? "" : ", ")
        << Fmt("{\"design\": %.0f, \"offset_mm\": [%.5f, ", match.design, e->offset_mm.x())
        << Fmt("%.5f], \"scale_pct\": %.5f, \"stretch_pct\": %.5f, ", e->offset_mm.y(), e->scale_pct,
               e->stretch_pct)
        << Fmt("\"local_rms_mm\": %.5f, \"local_max_mm\": %.5f, ", e->local_rms_mm, e->local_max_mm)
        << "\"points\": " << measured[match.measured].size() << "}";
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
    for (const auto& p : design[match.design]) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    const double x = static_cast<double>(match.design);
    off_s.x.push_back(x), off_s.y.push_back(1e3 * e->offset_mm.norm());
    scale_s.x.push_back(x), scale_s.y.push_back(1e3 * (std::abs(e->scale_pct) + e->stretch_pct) *
                                                    0.01 * 0.5 * (hi - lo).norm());
    local_s.x.push_back(x), local_s.y.push_back(1e3 * e->local_rms_mm);
    local_m.x.push_back(x), local_m.y.push_back(1e3 * e->local_max_mm);
    errors.push_back(std::move(*e));
  }
  per << "]";
  report.extra_json["contours"] = per.str();
  if (!matches.empty()) {
    const double n = static_cast<double>(matches.size());
    report.metrics["contour_offset_x_mm"] = offset_sum.x() / n;
    report.metrics["contour_offset_y_mm"] = offset_sum.y() / n;
    report.metrics["contour_scale_pct"] = scale_sum / n;
    report.metrics["contour_stretch_pct"] = stretch_sum / n;
    report.metrics["contour_local_error_max_mm"] = local_max;
  }
  if (matches.size() < contours.size()) {
    report.warnings.push_back(std::to_string(contours.size() - matches.size()) + " of " +
                              std::to_string(contours.size()) +
                              " design contours have no measured contour within " +
                              Fmt("%.1f mm", g.match_distance_mm));
  }
  // Plots: the contours coloured by local error (after offset and scale), the split, one profile.
  for (size_t k = 0; k < errors.size(); ++k) {
    const inspect::ContourError& e = errors[k];
    PlotSeries d{k == 0 ? "design" : "", {}, {}, 0x909090};
    for (const auto& p : e.design) d.x.push_back(p.x()), d.y.push_back(p.y());
    if (!e.design.empty()) d.x.push_back(e.design.front().x()), d.y.push_back(e.design.front().y());
    map.series.push_back(d);
  }
  constexpr int kBins = 6;
  std::vector<PlotSeries> bins(kBins);
  for (int b = 0; b < kBins; ++b) {
    bins[b].rgb = Heat((b + 0.5) / kBins);
    bins[b].label = Fmt("local error %.1f-%.1f um", 1e3 * local_max * b / kBins,
                        1e3 * local_max * (b + 1) / kBins);
  }
  for (const inspect::ContourError& e : errors) {
    for (size_t i = 0; i < e.design.size(); ++i) {
      if (i >= e.local_after_scale_mm.size() || e.matched[i] < 0) continue;
      const int b = std::min(kBins - 1, static_cast<int>(kBins * e.local_after_scale_mm[i] /
                                                         std::max(local_max, 1e-9)));
      // A short dash across the design point, so each centre shows.
      bins[b].x.insert(bins[b].x.end(), {e.design[i].x() - 0.3, e.design[i].x() + 0.3, NAN});
      bins[b].y.insert(bins[b].y.end(), {e.design[i].y(), e.design[i].y(), NAN});
    }
  }
  for (auto& b : bins) map.series.push_back(std::move(b));
  if (SavePlotPng(map, (dir / "contours.png").string()).ok()) report.artifacts["contours_plot"] = "contours.png";
  split.series = {off_s, scale_s, local_s, local_m};
  if (!errors.empty() && SavePlotPng(split, (dir / "error_split.png").string()).ok()) {
    report.artifacts["error_split_plot"] = "error_split.png";
  }
  for (const ProfileRecord& r : records) {
    if (!r.groove.ok) continue;
    PlotSpec ps;
    ps.title = Fmt("One profile across the groove (seed 002 Fig. 3): width %.1f um, depth %.1f um",
                   1e3 * r.groove.width_mm, 1e3 * r.groove.depth_mm);
    ps.x_label = "x along the profiler's line (mm)";
    ps.y_label = "z (mm)";
    PlotSeries pts{"profile", {}, {}, PlotColor(0)};
    for (size_t i = 0; i < r.profile.z_mm.size(); ++i) {
      pts.x.push_back(r.profile.x_start_mm + static_cast<double>(i) * r.profile.dx_mm);
      pts.y.push_back(r.profile.z_mm[i]);
    }
    ps.series.push_back(pts);
    {
      // The fitted template (eq. 11), drawn level about the groove (the profile's tilt here is
      // a few thousandths).
      const double w = r.groove.template_width_mm, d = r.groove.template_depth_mm;
      const double dd = d / std::tanh(0.25 * alpha * w);
      PlotSeries t{Fmt("template, alpha %.0f /mm", alpha), {}, {}, PlotColor(2)};
      for (double x : pts.x) {
        const double u = x - r.groove.x_mm;
        t.x.push_back(x);
        t.y.push_back(r.groove.z_mm + 0.5 * dd * (std::tanh(alpha * (u - 0.25 * w)) -
                                                   std::tanh(alpha * (u + 0.25 * w))));
      }
      ps.series.push_back(t);
    }
    const double half = 0.25 * r.groove.width_mm;
    PlotSeries marks{"centre and half-depth points", {r.groove.x_mm - half, r.groove.x_mm, r.groove.x_mm + half},
                     {r.groove.z_mm - 0.5 * r.groove.depth_mm, r.groove.z_mm - r.groove.depth_mm,
                      r.groove.z_mm - 0.5 * r.groove.depth_mm},
                     PlotColor(3)};
    ps.series.push_back(marks);
    if (SavePlotPng(ps, (dir / "profile.png").string()).ok()) report.artifacts["profile_plot"] = "profile.png";
    break;
  }
  return finish(true, "");
}

Status CheckCalibrateProfilerJob(const LoadedJob& job) {
  ConfigReader r(job.root);
  MachineSpec machine;
  ReadJobHeader(r, job, &machine);
  ProfilerSpec p;
  ReadProfilerSection(r.Section("profiler"), job.folder, &p);
  ConfigReader& out = r.Section("output");
  out.Skip("mount_file");
  return r.Finish();
}

Result<Report> RunCalibrateProfilerJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  ConfigReader r(job.root);
  MachineSpec machine;
  ReadJobHeader(r, job, &machine);
  ProfilerSpec p;
  ReadProfilerSection(r.Section("profiler"), job.folder, &p);
  std::string mount_file;
  ConfigReader& out = r.Section("output");
  out.Read("mount_file", &mount_file);
  INSITU_RETURN_IF_ERROR(r.Finish());
  hw::MachineConfig config;
  INSITU_RETURN_IF_ERROR(MachineConfigFor(job, machine, &config));
  auto block = BlockOf(p);
  if (!block.ok()) return block.status().Prefixed(job.path + ": profiler.block");
  INSITU_ASSIGN_OR_RETURN(
      hw::Machine m, OpenCell(config, options, {hw::Role::kAxis, hw::Role::kProfiler}, job));
  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir, m.warnings));
  const fs::path dir(options.out_dir);
  PhaseProgress progress(options, "block", "steps", 1);
  auto cal = CalibrateMountOnBlock(*m.axis, *m.profiler, *block, MountFromPose(p.drawing),
                                   p.block_scan, options.cancel);
  if (!cal.ok()) {
    return FinishReport(report, false, "profiler calibration: " + cal.status().ToString(),
                        wall_start, options.out_dir, StatusCode::kDeviceError);
  }
  progress.Update(1);
  const std::string path =
      mount_file.empty()
          ? (dir / "mount.yaml").string()
          : OutputPath(ResolvePath(job.folder, mount_file), "output.mount_file", options,
                       &report.warnings);
  const Status saved = SaveMount(*cal, m.profiler->info(), path);
  if (!saved.ok()) {
    return FinishReport(report, false, saved.ToString(), wall_start, options.out_dir,
                        StatusCode::kDeviceError);
  }
  report.artifacts["mount"] = path;
  const std::array<double, 6> pose = PoseFromMount(cal->mount);
  const char* names[6] = {"mount_x_mm", "mount_y_mm", "mount_z_mm",
                          "mount_rx_deg", "mount_ry_deg", "mount_rz_deg"};
  for (int k = 0; k < 6; ++k) report.metrics[names[k]] = pose[k];
  report.metrics["mount_fit_rms_um"] = 1e3 * cal->rms_mm;
  report.metrics["mount_points"] = cal->points;
  for (int k = 0; k < 6; ++k) {
    report.metrics[std::string("mount_stderr_") + inspect::kMountParameterNames[k]] =
        cal->standard_error[k];
  }
  return FinishReport(report, true, "", wall_start, options.out_dir, StatusCode::kDeviceError);
}

}  // namespace insitu::job
