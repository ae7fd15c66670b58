// The field_calibration job: the machine measures its own scan head (seeds 001 and 003).
//
//  1. Plate: the operator lays the chessboard flat on the stage plate; its corners give the
//     camera's pose against the plate (metric: the board's squares give the scale, not the
//     head), then the board is taken away.
//  2. Pointer: the red pointer is parked on every grid node; its spots, on the same plate,
//     give the pointer's path against the marking beam once the head is known.
//  3. Targets: on a fresh sacrificial plate the marking laser marks seed 003's spiral-filled
//     discs at an n x n grid of commands and at the centres of the grid's cells (the check
//     points, never used in a fit), with the head as it is (no correction).
//  4. Measure: the side camera finds every disc; its sub-pixel edge goes onto the plate plane
//     and a circle fitted there gives the perspective-correct centre (seed 003's minimum
//     enclosing circle is reported beside it).
//  5. Fit: the physical head (optics/scan_head.h, Ceres) on the grid, which also places the
//     plate frame in the galvo frame; the n x n bilinear lookups, seed 003's quadrant fit and
//     physics plus a table of what it leaves are compared at the check points.
//  6. Close the loop (seed 001's second pass): a fresh plate, the same targets marked through
//     the correction, measured again in the same frame: before and after at the check points.
//  7. The machine calibration gets the measured head, the pointer's path and the camera's pose
//     in the galvo frame (camera from plate, plate from galvo), so every later scan and mark
//     uses what was measured. Nothing is written unless every step succeeded.
#include "job/field_calibration.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>

#include "insitu/calib/calibration.h"
#include "insitu/calib/camera_calibration.h"
#include "insitu/core/file.h"
#include "insitu/core/log.h"
#include "insitu/fit/field_models.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/job/plot.h"
#include "insitu/pattern/correction_table.h"
#include "insitu/pattern/spiral_target.h"
#include "insitu/vision/circle_targets.h"
#include "insitu/vision/crosses.h"
#include "insitu/vision/resample.h"
#include "insitu/vision/targets.h"
#include "job/cell.h"
#include "job/coaxial_field.h"
#include "job/output_path.h"
#include "job/progress.h"
#include "job/room_exposure.h"
#include "job/save_calibration.h"

namespace insitu::job {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

struct FieldSpec {
  MachineSpec machine;
  int n = 11;                    // grid nodes per side
  double half_size_mm = 60.0;    // grid from -half to +half in x and y
  bool check_points = true;      // the cell centres, measured but never fitted
  // spiral: discs marked by the marking laser (seed 003); cross: seed 001's marked "+";
  // pointer: the non-destructive variant, the pointer's spot parked on a matte card (measures
  // the pointer's field, not the laser's).
  std::string target_kind = "spiral";
  // side: the side camera measures targets over the whole field; coaxial: the coaxial camera
  // measures the head's aim on a reticle over a small field (seed 001).
  std::string route = "side";
  CoaxialFieldOptions coaxial;
  pattern::SpiralTargetOptions spiral;
  // Seen by the side camera at ~0.09 mm per pixel: bars 5 px wide and 55 px long, so each
  // bar's centre line rests on ~50 cross-sections (seed 001's 0.1 mm bars suit its coaxial
  // camera at a few micrometres per pixel).
  pattern::CrossTargetOptions cross{5.0, 0.4, 0.035};
  double mark_speed_mm_per_s = 1000.0;
  double jump_speed_mm_per_s = 5000.0;
  double laser_power = 0.5;
  double laser_frequency_khz = 30.0;
  calib::BoardGeometry board{9, 6, 8.0};
  double board_thickness_mm = 2.0;
  double board_exposure_ms = 300.0;
  bool board_auto_exposure = true;  // set on the board as it lies (job/room_exposure.h)
  double target_exposure_ms = 300.0;
  bool pointer = true;
  double pointer_exposure_ms = 0.5;
  // Stage heights of the pointer's spots: two or more let the mirror separation be fitted
  // (it tilts the chief rays, which only spots off the focal plane see).
  std::vector<double> pointer_stage_z_mm{0.0, 15.0};
  bool verify = true;            // the second pass
  // The second pass must measure at most this at the check points, or nothing is saved; 0:
  // 10 um for marked targets (the bar), 50 um for pointer spots (~19 um scatter each).
  double max_error_rms_um_after = 0.0;
  fit::HeadFitOptions head_fit;
  bool residual_table = true;    // physics plus a table of what it leaves
  int correction_nodes = 65;     // correction.csv: nodes per side over the grid
  std::string output_path;
};

std::string Num(double v, int digits = 3) {
  char b[48];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

Status ReadSpec(const LoadedJob& job, FieldSpec* s, hw::MachineConfig* machine) {
  ConfigReader r(job.root);
  ReadJobHeader(r, job, &s->machine);
  r.ReadEnum("route", &s->route, {"side", "coaxial"});
  if (r.Has("coaxial")) {
    ConfigReader& c = r.Section("coaxial");
    c.Read("half_size_mm", &s->coaxial.half_size_mm);
    c.Read("n", &s->coaxial.n);
    c.Read("check_points", &s->coaxial.check_points);
    c.Read("surface_z_mm", &s->coaxial.surface_z_mm);
    c.Read("reticle_pitch_mm", &s->coaxial.reticle_pitch_mm);
    c.Read("exposure_us", &s->coaxial.exposure_us);
    c.Read("image_mirrored", &s->coaxial.image_mirrored);
    if (c.ok()) c.FailFromValidate(s->coaxial.Validate());
  }
  ConfigReader& g = r.Section("grid");
  g.Read("n", &s->n);
  g.Read("half_size_mm", &s->half_size_mm);
  g.Read("check_points", &s->check_points);
  if (g.ok() && (s->n < 5 || s->n > 65)) g.Fail("n", "must be in 5..65");
  if (g.ok() && !(s->half_size_mm > 0)) g.Fail("half_size_mm", "must be > 0");
  ConfigReader& t = r.Section("target");
  t.ReadEnum("kind", &s->target_kind, {"spiral", "cross", "pointer"});
  t.Read("diameter_mm", &s->spiral.diameter_mm);
  t.Read("pitch_mm", &s->spiral.pitch_mm);
  t.Read("length_mm", &s->cross.length_mm);
  t.Read("bar_width_mm", &s->cross.bar_width_mm);
  t.Read("exposure_ms", &s->target_exposure_ms);
  s->cross.line_width_mm = s->spiral.pitch_mm;  // one marked line width for both targets
  if (t.ok()) t.FailFromValidate(s->spiral.Validate());
  if (t.ok() && s->target_kind == "cross") t.FailFromValidate(s->cross.Validate());
  if (g.ok() && t.ok() && s->target_kind != "pointer") {
    // A check point sits half a diagonal pitch from four nodes: targets must not touch there.
    const double pitch = 2.0 * s->half_size_mm / (s->n - 1);
    const double gap = (s->check_points ? 0.5 * std::sqrt(2.0) : 1.0) * pitch;
    const double size = s->target_kind == "cross" ? s->cross.length_mm : s->spiral.diameter_mm;
    if (gap < 1.5 * size) {
      g.Fail("n", "targets " + Num(size, 2) + " mm across would lie " + Num(gap, 2) +
                      " mm apart (centre to centre) on this grid: fewer nodes or a wider grid "
                      "(at least 1.5 target sizes apart)");
    }
  }
  if (t.ok() && !(s->target_exposure_ms > 0)) t.Fail("exposure_ms", "must be > 0");
  ConfigReader& m = r.Section("marking");
  m.Read("mark_speed_mm_per_s", &s->mark_speed_mm_per_s);
  m.Read("jump_speed_mm_per_s", &s->jump_speed_mm_per_s);
  m.Read("power", &s->laser_power);
  m.Read("frequency_khz", &s->laser_frequency_khz);
  if (m.ok() && !(s->mark_speed_mm_per_s > 0)) m.Fail("mark_speed_mm_per_s", "must be > 0");
  if (m.ok() && !(s->jump_speed_mm_per_s > 0)) m.Fail("jump_speed_mm_per_s", "must be > 0");
  if (m.ok() && !(s->laser_power > 0 && s->laser_power <= 1)) m.Fail("power", "must be in (0, 1]");
  if (m.ok() && !(s->laser_frequency_khz > 0)) m.Fail("frequency_khz", "must be > 0");
  ConfigReader& b = r.Section("board");
  b.Read("inner_cols", &s->board.inner_cols);
  b.Read("inner_rows", &s->board.inner_rows);
  b.Read("square_mm", &s->board.square_mm);
  b.Read("thickness_mm", &s->board_thickness_mm);
  b.Read("exposure_ms", &s->board_exposure_ms);
  b.Read("auto_exposure", &s->board_auto_exposure);
  if (b.ok() && (s->board.inner_cols < 3 || s->board.inner_rows < 3)) {
    b.Fail("inner_cols", "must be >= 3 (and inner_rows)");
  }
  if (b.ok() && !(s->board.square_mm > 0)) b.Fail("square_mm", "must be > 0");
  if (b.ok() && !(s->board_thickness_mm >= 0)) b.Fail("thickness_mm", "must be >= 0");
  if (b.ok() && !(s->board_exposure_ms > 0)) b.Fail("exposure_ms", "must be > 0");
  if (r.Has("pointer")) {
    ConfigReader& p = r.Section("pointer");
    p.Read("enabled", &s->pointer);
    p.Read("exposure_ms", &s->pointer_exposure_ms);
    p.Read("stage_z_mm", &s->pointer_stage_z_mm);
    if (p.ok() && !(s->pointer_exposure_ms > 0)) p.Fail("exposure_ms", "must be > 0");
    if (p.ok() && s->pointer_stage_z_mm.empty()) p.Fail("stage_z_mm", "must list at least one height");
  }
  if (r.Has("fit")) {
    ConfigReader& f = r.Section("fit");
    f.Read("focal_length", &s->head_fit.fit_focal_length);
    f.Read("ftheta_distortion", &s->head_fit.fit_ftheta_distortion);
    f.Read("axis_tilt", &s->head_fit.fit_axis_tilt);
    f.Read("y_axis_tilt", &s->head_fit.fit_y_axis_tilt);
    f.Read("zero_offsets", &s->head_fit.fit_zero_offsets);
    f.Read("residual_table", &s->residual_table);
  }
  r.Read("verify", &s->verify);
  r.Read("max_error_rms_um_after", &s->max_error_rms_um_after);
  if (r.ok() && !(s->max_error_rms_um_after >= 0)) r.Fail("max_error_rms_um_after", "must be >= 0");
  if (s->max_error_rms_um_after == 0) {
    s->max_error_rms_um_after =
        s->route == "coaxial" ? 3.0 : s->target_kind == "pointer" ? 50.0 : 10.0;
  }
  ConfigReader& out = r.Section("output");
  out.Require("calibration");
  std::string path;
  out.Read("calibration", &path);
  out.Read("correction_nodes", &s->correction_nodes);
  if (out.ok() && (s->correction_nodes < 2 || s->correction_nodes > 257)) {
    out.Fail("correction_nodes", "must be in 2..257");
  }
  s->output_path = ResolvePath(job.folder, path);
  INSITU_RETURN_IF_ERROR(r.Finish());
  return MachineConfigFor(job, s->machine, machine);
}

struct Target {
  Vector2d nominal;         // where it is asked for, galvo frame
  bool check = false;
  Vector3d command;         // what was sent
  std::optional<Vector2d> plate;      // measured centre, plate frame (edge circle)
  std::optional<Vector2d> plate_mec;  // seed 003's centre (minimum enclosing circle), plate frame
};

std::vector<Target> Layout(const FieldSpec& s) {
  std::vector<Target> t;
  const double step = 2.0 * s.half_size_mm / (s.n - 1);
  for (int j = 0; j < s.n; ++j) {
    for (int i = 0; i < s.n; ++i) {
      t.push_back({{-s.half_size_mm + i * step, -s.half_size_mm + j * step}, false, {}, {}, {}});
    }
  }
  if (s.check_points) {
    for (int j = 0; j + 1 < s.n; ++j) {
      for (int i = 0; i + 1 < s.n; ++i) {
        t.push_back({{-s.half_size_mm + (i + 0.5) * step, -s.half_size_mm + (j + 0.5) * step},
                     true, {}, {}, {}});
      }
    }
  }
  return t;
}

// A target's shape: strokes in target coordinates (mm), each a polyline the laser marks from
// a jump to its first point.
using Strokes = std::vector<std::vector<Vector2d>>;
Result<Strokes> TargetStrokes(const FieldSpec& s) {
  if (s.target_kind == "cross") {
    INSITU_ASSIGN_OR_RETURN(std::vector<pattern::Segment2> bars, pattern::CrossTargetStrokes(s.cross));
    Strokes out;
    for (const pattern::Segment2& b : bars) out.push_back({b.a, b.b});
    return out;
  }
  INSITU_ASSIGN_OR_RETURN(std::vector<Vector2d> spiral, pattern::SpiralTargetPath(s.spiral));
  return Strokes{std::move(spiral)};
}
// How far a target reaches from its centre, mm.
double TargetRadius(const FieldSpec& s) {
  return s.target_kind == "cross" ? 0.5 * s.cross.length_mm : 0.5 * s.spiral.diameter_mm;
}

// The list that marks every target: each target's strokes through the local linear map of the
// correction at its centre (the correction varies by < 1e-2 over a target, so its centre lands
// where the correction sends it and the target keeps its shape to a few micrometres).
using CommandMap = std::function<bool(const Vector3d&, Vector3d*)>;
Result<hw::GalvoList> TargetList(const FieldSpec& s, const Strokes& shape,
                                 std::vector<Target>* targets, const CommandMap& command_for) {
  hw::GalvoList list;
  list.mark_speed_mm_per_s = s.mark_speed_mm_per_s;
  list.jump_speed_mm_per_s = s.jump_speed_mm_per_s;
  list.laser_power = s.laser_power;
  list.laser_frequency_khz = s.laser_frequency_khz;
  constexpr double kH = 0.5;  // mm: the local map's finite-difference step
  for (Target& t : *targets) {
    const Vector3d c(t.nominal.x(), t.nominal.y(), 0.0);
    Vector3d c0, cx, cy;
    if (!command_for(c, &c0) || !command_for(c + Vector3d(kH, 0, 0), &cx) ||
        !command_for(c + Vector3d(0, kH, 0), &cy)) {
      return OutOfRange("the correction cannot reach the target at (" + Num(c.x()) + ", " +
                        Num(c.y()) + ") mm");
    }
    Eigen::Matrix2d j;
    j.col(0) = (cx - c0).head<2>() / kH;
    j.col(1) = (cy - c0).head<2>() / kH;
    t.command = c0;
    for (const std::vector<Vector2d>& stroke : shape) {
      for (size_t k = 0; k < stroke.size(); ++k) {
        const Vector2d p = c0.head<2>() + j * stroke[k];
        list.entries.push_back({k == 0 ? hw::GalvoListEntry::Kind::kJump
                                       : hw::GalvoListEntry::Kind::kMark,
                                Vector3d(p.x(), p.y(), 0.0)});
      }
    }
  }
  return list;
}

// "target (x, y) mm near pixel (u, v)", for warnings.
std::string Where(const Target& t, const Vector2d& predicted_px) {
  return (t.check ? "check point (" : "target (") + Num(t.nominal.x(), 2) + ", " +
         Num(t.nominal.y(), 2) + ") mm near pixel (" + Num(predicted_px.x(), 0) + ", " +
         Num(predicted_px.y(), 0) + ")";
}

// Finds the targets in a frame and measures each centre on the plate. Each expected target
// is matched to the detection nearest its predicted pixel, within 40 % of the grid pitch
// (seed 001 sec. 3.3: the error must stay under half the pitch or the match is ambiguous).
Status MeasureTargets(const Frame& frame, const calib::CameraIntrinsics& cam,
                      const Eigen::Isometry3d& camera_from_plate,
                      const Eigen::Isometry3d& camera_from_galvo_guess, double pitch_mm,
                      const vision::CircleTargetOptions& options, std::vector<Target>* targets,
                      std::vector<std::string>* warnings, int* found) {
  std::vector<vision::RejectedBlob> rejected;
  INSITU_ASSIGN_OR_RETURN(std::vector<vision::CircleTarget> blobs,
                          vision::FindCircleTargets(vision::ViewOf(frame), options, &rejected));
  std::vector<Vector2d> blob_px;
  for (const vision::CircleTarget& b : blobs) blob_px.push_back(b.centroid_px);
  std::vector<bool> used(blobs.size(), false);
  *found = 0;
  for (Target& t : *targets) {
    t.plate.reset();
    t.plate_mec.reset();
    const Vector3d in_cam = camera_from_galvo_guess * Vector3d(t.nominal.x(), t.nominal.y(), 0.0);
    const Vector2d predicted = cam.Project(in_cam);
    const Vector3d in_cam_next =
        camera_from_galvo_guess * Vector3d(t.nominal.x() + pitch_mm, t.nominal.y(), 0.0);
    const double pitch_px = (cam.Project(in_cam_next) - predicted).norm();
    int best = -1;
    double best_d = 0.4 * pitch_px;
    for (size_t k = 0; k < blobs.size(); ++k) {
      const double d = (blob_px[k] - predicted).norm();
      if (d < best_d && !used[k]) {
        best = static_cast<int>(k);
        best_d = d;
      }
    }
    const std::string where = Where(t, predicted);
    if (best < 0) {
      std::string why;
      for (const vision::RejectedBlob& r : rejected) {
        if ((r.center_px - predicted).norm() < 0.4 * pitch_px) why = ": a blob there was rejected: " + r.reason;
      }
      warnings->push_back(where + " not found" + why);
      continue;
    }
    used[best] = true;
    const vision::CircleTarget& b = blobs[best];
    std::vector<Vector2d> edge_mm;
    for (const auto& p : calib::PixelsOnPlane(b.edge_px, cam, camera_from_plate)) {
      if (p) edge_mm.push_back(*p);
    }
    auto circle = vision::FitCircle(edge_mm);
    if (!circle.ok()) {
      warnings->push_back(where + ": its edge gives no circle: " + circle.status().message());
      continue;
    }
    t.plate = circle->center;
    const auto mec = calib::PixelsOnPlane({b.mec_center_px}, cam, camera_from_plate);
    if (mec[0]) t.plate_mec = *mec[0];
    ++*found;
  }
  return Status::Ok();
}

// Seed 001's crosses seen by the side camera. The camera looks at the plate at ~30 degrees,
// so a "+" on the plate is a skewed cross in the frame; each target's neighbourhood is
// therefore resampled onto the plate plane first (the camera's ray through every sample, lens
// distortion included, meets the plate: the homography of seed 003 with the lens model), at
// the camera's finest native sampling there, and the cross is found in that plate-aligned
// patch: its two bars are straight and square again, and its centre maps back to plate mm by a
// scale. Matched as the discs are: the cross nearest the predicted position, within 40 % of
// the grid pitch.
Status MeasureCrossTargets(const Frame& frame, const calib::CameraIntrinsics& cam,
                           const Eigen::Isometry3d& camera_from_plate,
                           const Eigen::Isometry3d& camera_from_galvo_guess, double pitch_mm,
                           const pattern::CrossTargetOptions& cross, std::vector<Target>* targets,
                           std::vector<std::string>* warnings, int* found) {
  const vision::ImageView image = vision::ViewOf(frame);
  const Eigen::Isometry3d plate_from_galvo = camera_from_plate.inverse() * camera_from_galvo_guess;
  const auto pixel_of = [&](const Vector2d& plate_mm) {
    return cam.Project(camera_from_plate * Vector3d(plate_mm.x(), plate_mm.y(), 0.0));
  };
  *found = 0;
  for (Target& t : *targets) {
    t.plate.reset();
    t.plate_mec.reset();
    const Vector2d centre = (plate_from_galvo * Vector3d(t.nominal.x(), t.nominal.y(), 0.0)).head<2>();
    const Vector2d predicted = pixel_of(centre);
    const std::string where = Where(t, predicted);
    // The finest native sampling at the target: the longer of the frame's steps for 1 mm
    // along the plate's x and y.
    const double px_per_mm = std::max((pixel_of(centre + Vector2d(1, 0)) - predicted).norm(),
                                      (pixel_of(centre + Vector2d(0, 1)) - predicted).norm());
    const double mm_per_px = 1.0 / px_per_mm;
    const int half = static_cast<int>(std::ceil(0.5 * pitch_mm * px_per_mm));
    const int size = 2 * half + 1;
    vision::PixelMap map{size, size, {}, {}};
    for (int r = 0; r < size; ++r) {
      for (int c = 0; c < size; ++c) {
        const Vector2d q = pixel_of(centre + mm_per_px * Vector2d(c - half, r - half));
        map.u.push_back(static_cast<float>(q.x()));
        map.v.push_back(static_cast<float>(q.y()));
      }
    }
    INSITU_ASSIGN_OR_RETURN(const vision::Image patch, vision::Remap(image, map));
    vision::CrossOptions options;
    options.bright = true;  // marks on black anodising scatter more light than the plate
    // A bar's image: its width plus the camera's blur (~2 px) and the resampling's pixel.
    options.max_line_width_px = cross.bar_width_mm * px_per_mm + 4.0;
    options.min_bar_px = 0.6 * cross.length_mm * px_per_mm;
    options.max_bar_px = 1.5 * cross.length_mm * px_per_mm + 4.0;
    auto crosses = vision::FindCrosses(patch.view(), options);
    if (!crosses.ok()) return crosses.status();
    const vision::Cross* best = nullptr;
    double best_d = 0.4 * pitch_mm * px_per_mm;
    for (const vision::Cross& x : *crosses) {
      const double d = (x.centre_px - Vector2d(half, half)).norm();
      if (d < best_d) {
        best = &x;
        best_d = d;
      }
    }
    if (best == nullptr) {
      warnings->push_back(where + " not found" +
                          (crosses->empty() ? std::string(": no cross in its neighbourhood")
                                            : ": " + std::to_string(crosses->size()) +
                                                  " crosses near it, none within 40 % of the pitch"));
      continue;
    }
    t.plate = centre + mm_per_px * (best->centre_px - Vector2d(half, half));
    ++*found;
  }
  return Status::Ok();
}

struct ErrorStats {
  double rms_um = 0, max_um = 0;
  int n = 0;
};
ErrorStats Stats(const std::vector<fit::GalvoSample>& s) {
  const fit::ModelError e = fit::NominalError(s);
  return {e.rms_mm * 1e3, e.max_mm * 1e3, static_cast<int>(s.size())};
}

Status WriteFieldCsv(const std::vector<Target>& targets, const Eigen::Isometry2d& galvo_from_plate,
                     const std::string& path) {
  std::ostringstream os;
  os.precision(10);
  os << "# insitu field calibration: commanded vs measured target centres, galvo frame, mm\n"
     << "# check = 1: a check point, never used in a fit\n"
     << "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm,check\n";
  for (const Target& t : targets) {
    if (!t.plate) continue;
    const Vector2d m = galvo_from_plate * *t.plate;
    os << t.command.x() << "," << t.command.y() << "," << m.x() << "," << m.y() << ","
       << (t.check ? 1 : 0) << "\n";
  }
  return WriteFileAtomically(path, os.str());
}

// What a board driving this head linearly must send for a command p so that the spot lands
// where the measured correction puts it (`delta(p)`: what to add to a command of the
// controller as it is now): the linear drive the controller gives p + delta(p) today. It comes
// from the scanner when it holds the table itself (an LMC board: its uploaded table), else from
// the head's design (a head that corrects itself: its controller inverts the design geometry,
// and the linear drive of those mirror angles is f_design times them). A table built from it
// replaces the board's own rather than adding to it. Galvo frame, mm.
std::function<Vector2d(const Vector2d&)> ControllerDrive(
    const hw::Scanner& scanner, const optics::HeadGeometry& design,
    std::function<Vector2d(double, double)> delta) {
  return [&scanner, design = optics::ScanOptics(design), delta = std::move(delta)](
             const Vector2d& p) {
    const Vector2d c = p + delta(p.x(), p.y());
    Vector2d drive;
    if (scanner.DriveCommand(c, &drive)) return drive;
    optics::MirrorAngles a;
    if (!design.Solve(c.x(), c.y(), 0.0, &a)) return c;  // beyond the design: drive as commanded
    return Vector2d(design.geometry().focal_length_mm * Vector2d(a.x_rad, a.y_rad));
  };
}

}  // namespace

Status CheckFieldCalibrationJob(const LoadedJob& job) {
  FieldSpec spec;
  hw::MachineConfig config;
  return ReadSpec(job, &spec, &config);
}

Result<Report> RunFieldCalibrationJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  FieldSpec spec;
  hw::MachineConfig config;
  INSITU_RETURN_IF_ERROR(ReadSpec(job, &spec, &config));
  auto previous = calib::LoadCalibration(spec.machine.calibration_path);
  if (!previous.ok()) return previous.status().Prefixed(job.path + ": machine.calibration");
  INSITU_ASSIGN_OR_RETURN(const Strokes shape, TargetStrokes(spec));
  // The side route marks a fresh plate the operator lays at the stage's zero; the coaxial route
  // looks through the head at a plate already there.
  INSITU_ASSIGN_OR_RETURN(
      hw::Machine machine,
      spec.route == "coaxial"
          ? OpenCell(config, options, {hw::Role::kScanner, hw::Role::kCamera, hw::Role::kCoaxial},
                     job)
          : OpenCell(config, options,
                     {hw::Role::kScanner, hw::Role::kCamera, hw::Role::kStage, hw::Role::kOperator},
                     job));
  const hw::CameraInfo info = machine.camera->info();
  INSITU_RETURN_IF_ERROR(calib::CheckCameraMatches(previous->camera, info.model, info.serial,
                                                   info.sensor_width_px, info.sensor_height_px)
                             .Prefixed(job.path + ": machine.calibration"));
  const hw::ScannerInfo head_info = machine.scanner->info();
  const double reach = spec.half_size_mm + TargetRadius(spec);
  if (head_info.field_half_size_mm > 0 && reach > head_info.field_half_size_mm) {
    return InvalidArgument(job.path + ": grid.half_size_mm: the grid with its targets reaches " +
                           Num(reach, 2) + " mm, beyond the head's field of +-" +
                           Num(head_info.field_half_size_mm, 2) + " mm");
  }
  if (spec.pointer && spec.route == "side") {  // the coaxial route never moves the stage
    const double lo = machine.stage->min_z_mm(), hi = machine.stage->max_z_mm();
    for (double z : spec.pointer_stage_z_mm) {
      if (z < lo || z > hi) {
        return InvalidArgument(job.path + ": pointer.stage_z_mm: " + Num(z, 2) +
                               " mm is outside the stage travel [" + Num(lo, 2) + ", " +
                               Num(hi, 2) + "] mm");
      }
    }
  }
  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir, machine.warnings));
  const std::filesystem::path dir(options.out_dir);
  // A failed measurement is failed_precondition; a device's fault or a cancel keeps its own
  // code (exit 1 or 130, not 2: the input was fine).
  auto finish = [&](bool ok, const std::string& error,
                    StatusCode code = StatusCode::kFailedPrecondition) {
    return FinishReport(report, ok, error, wall_start, options.out_dir, code);
  };
  auto fail = [&](const std::string& prefix, const Status& st) {
    return finish(false, prefix + st.ToString(), st.code());
  };
  const auto cancelled = [&] { return options.cancel != nullptr && options.cancel->load(); };
  auto log = Logger("job");
  if (previous->produced_by == "as_designed") {
    report.warnings.push_back(
        "the calibration is the as-designed file: run the calibrate job first (the camera's "
        "intrinsics measure the targets)");
  }
  if (spec.route == "coaxial") {
    // Seed 001: the head's aim on the reticle lying on the stage. The result is a table for
    // that small field (correction.csv, for head.correction); the machine calibration is not
    // changed: it holds the whole field's head from the side camera's route.
    std::vector<std::string> warnings;
    spec.coaxial.second_pass = spec.verify;
    auto r = MeasureCoaxialField(machine, spec.coaxial, options, &warnings);
    report.warnings.insert(report.warnings.end(), warnings.begin(), warnings.end());
    if (!r.ok()) return fail("coaxial: ", r.status());
    report.metrics["check_points"] = static_cast<double>(r->check.size());
    report.metrics["targets_expected"] = static_cast<double>(r->grid.size() + r->check.size());
    report.metrics["targets_found"] = static_cast<double>(r->grid.size() + r->check.size());
    report.metrics["field_error_rms_um_before"] = r->rms_um_before;
    report.metrics["field_error_max_um_before"] = r->max_um_before;
    report.metrics["coaxial_pixel_um"] = r->pixel_um;
    report.metrics["coaxial_rotation_deg"] = r->rotation_deg;
    if (spec.verify) {
      report.metrics["field_error_rms_um_after"] = r->rms_um_after;
      report.metrics["field_error_max_um_after"] = r->max_um_after;
      report.metrics["distortion_removed_pct"] =
          r->rms_um_before > 0 ? 100.0 * (1.0 - r->rms_um_after / r->rms_um_before) : 0.0;
    }
    std::string refused;
    if (spec.verify) {
      const bool must_improve = r->rms_um_before > spec.max_error_rms_um_after;
      if (r->rms_um_after > spec.max_error_rms_um_after ||
          (must_improve && r->rms_um_after >= r->rms_um_before)) {
        refused = "coaxial second pass: the corrected field measures " + Num(r->rms_um_after, 2) +
                  " um rms at the check points (before: " + Num(r->rms_um_before, 2) +
                  " um; accepted: up to " + Num(spec.max_error_rms_um_after, 2) +
                  " um, and less than before when before was above that); no correction.csv "
                  "was written";
      }
    }
    if (refused.empty()) {
      const pattern::CorrectionTable table(r->correction);
      if (WriteFileAtomically((dir / "correction.csv").string(), table.ToCsv()).ok()) {
        report.artifacts["correction"] = "correction.csv";
      }
      report.warnings.push_back(
          "correction.csv covers the coaxial field only (+-" + Num(spec.coaxial.half_size_mm, 2) +
          " mm); beyond it a table repeats its edge offsets: use it as head.correction only for "
          "work inside that field");
    }
    std::vector<Target> all;
    for (const auto* set : {&r->grid, &r->check}) {
      for (const fit::GalvoSample& g : *set) {
        Target t{g.cmd.head<2>(), set == &r->check, g.cmd, g.meas, {}};
        all.push_back(t);
      }
    }
    if (WriteFieldCsv(all, Eigen::Isometry2d::Identity(), (dir / "field.csv").string()).ok()) {
      report.artifacts["field"] = "field.csv";
    }
    log->info("coaxial: {:.2f} um rms before, {:.2f} um after at {} check points",
              r->rms_um_before, r->rms_um_after, r->check.size());
    if (!refused.empty()) return finish(false, refused);
    return finish(true, "");
  }
  const calib::CameraIntrinsics& cam = previous->camera;
  const double pitch = 2.0 * spec.half_size_mm / (spec.n - 1);

  // 1. The plate's plane from the board lying on it.
  for (const Status& st : {machine.camera->SetBinning(1), machine.stage->MoveTo(0.0),
                           machine.scanner->StopPointer(), machine.person->ClearTable(),
                           machine.camera->SetExposure(spec.board_exposure_ms * 1e3)}) {
    if (!st.ok()) return fail("plate: ", st);
  }
  const Status laid = machine.person->PlaceBoardOnPlate();
  if (!laid.ok()) {
    return finish(false,
                  "no plate plane: the board could not be laid on the plate: " + laid.ToString(),
                  laid.code());
  }
  if (spec.board_auto_exposure) {
    auto exposed = ExposeForBoard(*machine.camera, spec.board_exposure_ms,
                                  spec.board_exposure_ms / 10.0, spec.board_exposure_ms * 10.0,
                                  {spec.board.inner_cols, spec.board.inner_rows}, options.cancel);
    if (!exposed.ok()) return fail("plate: ", exposed.status());
    report.metrics["board_exposure_ms"] = exposed->exposure_ms;
    if (!exposed->note.empty()) report.warnings.push_back("plate: " + exposed->note);
  }
  auto board_frame = machine.camera->Grab();
  if (!board_frame.ok()) return fail("plate: ", board_frame.status());
  auto corners = vision::FindChessboard(vision::ViewOf(*board_frame),
                                        {spec.board.inner_cols, spec.board.inner_rows});
  const Status removed = machine.person->RemoveBoard();
  if (!removed.ok()) return fail("plate: ", removed);
  if (!corners.ok()) {
    return finish(false, "no plate plane: the board lying on the plate was not found: " +
                             corners.status().message());
  }
  const calib::PlatePoseSummary plate =
      calib::PlateFromBoard(*corners, spec.board, cam, spec.board_thickness_mm);
  if (!plate.ok) return finish(false, "no plate plane: " + plate.message);
  report.metrics["plate_board_rms_px"] = plate.rms_px;
  log->info("plate: board found, corner reprojection {:.3f} px rms", plate.rms_px);

  // 2. The pointer on every grid node.
  std::vector<Target> targets = Layout(spec);
  // Parks the pointer on each command (uncorrected commands through `command_for`) and finds
  // its spot on the plate: the spot's centroid against a dark frame (pointer off).
  struct PointerSpot {
    Vector3d cmd;
    Vector2d plate;
  };
  // `plane_z`: the plate's top in the galvo frame (the stage's height: it moves along z).
  const auto measure_spots = [&](const std::string& phase, const std::vector<Vector3d>& commands,
                                 double plane_z,
                                 std::vector<std::optional<Vector2d>>* on_plate) -> Status {
    INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(spec.pointer_exposure_ms * 1e3));
    (void)machine.scanner->StopPointer();
    auto dark = machine.camera->Grab();
    if (!dark.ok()) return dark.status();
    PhaseProgress progress(options, phase, "spots", static_cast<double>(commands.size()));
    on_plate->assign(commands.size(), std::nullopt);
    for (size_t k = 0; k < commands.size(); ++k) {
      if (cancelled()) return Status(StatusCode::kCancelled, "cancelled");
      const Vector3d& p = commands[k];
      INSITU_RETURN_IF_ERROR(machine.scanner->StartPointerLine(p, p, 1.0));
      machine.clock->SleepFor(0.005);
      auto lit = machine.camera->Grab();
      if (!lit.ok()) return lit.status();
      auto spot = vision::FindSpot(vision::ViewOf(*lit), vision::ViewOf(*dark), {});
      progress.Update(static_cast<double>(k + 1));
      if (!spot.ok()) {
        report.warnings.push_back(phase + " at (" + Num(p.x(), 2) + ", " + Num(p.y(), 2) +
                                  ") mm: " + spot.status().message());
        continue;
      }
      (*on_plate)[k] = calib::PixelsOnPlane(
          {spot->center}, cam,
          plate.camera_from_plate * Eigen::Translation3d(0.0, 0.0, plane_z))[0];
    }
    return machine.scanner->StopPointer();
  };
  const bool by_pointer = spec.target_kind == "pointer";
  std::vector<PointerSpot> pointer_spots;
  if (spec.pointer && !by_pointer) {
    for (double z : spec.pointer_stage_z_mm) {
      const Status moved = machine.stage->MoveTo(z);
      if (!moved.ok()) return fail("pointer: ", moved);
      std::vector<Vector3d> nodes;
      for (const Target& t : targets) {
        if (!t.check) nodes.emplace_back(t.nominal.x(), t.nominal.y(), z);
      }
      std::vector<std::optional<Vector2d>> on_plate;
      const Status st = measure_spots("pointer spot", nodes, z, &on_plate);
      if (!st.ok()) return fail("pointer: ", st);
      for (size_t k = 0; k < nodes.size(); ++k) {
        if (on_plate[k]) pointer_spots.push_back({nodes[k], *on_plate[k]});
      }
    }
    const Status back = machine.stage->MoveTo(0.0);
    if (!back.ok()) return fail("pointer: ", back);
  }

  // 3-4. Mark the targets as the head is, and measure them.
  vision::CircleTargetOptions find;
  {
    // Expected disc diameter in pixels, from the camera's scale at the field centre.
    const Vector3d c0 = previous->galvo.camera_from_galvo * Vector3d::Zero();
    const double px_per_mm = cam.fx / c0.z();
    const double d_px = spec.spiral.diameter_mm * px_per_mm;
    find.min_diameter_px = std::max(4.0, 0.5 * d_px);
    find.max_diameter_px = 2.0 * d_px;
  }
  const auto mark_and_measure = [&](const std::string& pass, const CommandMap& command_for,
                                    int* found) -> Status {
    if (by_pointer) {
      // The non-destructive variant: the pointer's spot stands for the target.
      std::vector<Vector3d> commands;
      for (Target& t : targets) {
        const Vector3d c(t.nominal.x(), t.nominal.y(), 0.0);
        if (!command_for(c, &t.command)) {
          return OutOfRange("the correction cannot reach (" + Num(c.x()) + ", " + Num(c.y()) + ") mm");
        }
        commands.push_back(t.command);
      }
      std::vector<std::optional<Vector2d>> on_plate;
      INSITU_RETURN_IF_ERROR(measure_spots(pass, commands, 0.0, &on_plate));
      *found = 0;
      for (size_t k = 0; k < targets.size(); ++k) {
        targets[k].plate = on_plate[k];
        targets[k].plate_mec.reset();
        if (!on_plate[k]) {
          report.warnings.push_back(std::string(targets[k].check ? "check point" : "target") +
                                    " (" + Num(targets[k].nominal.x(), 2) + ", " +
                                    Num(targets[k].nominal.y(), 2) + ") mm not found");
        }
        *found += on_plate[k] ? 1 : 0;
      }
      return Status::Ok();
    }
    auto list = TargetList(spec, shape, &targets, command_for);
    if (!list.ok()) return list.status();
    hw::ListControl control;
    control.abort = options.cancel;
    PhaseProgress progress(options, pass, "list", 1.0);
    control.progress = [&](double f) { progress.Update(f); };
    INSITU_RETURN_IF_ERROR(machine.scanner->Arm());
    const Status ran = machine.scanner->ExecuteList(*list, control);
    (void)machine.scanner->Disarm();
    INSITU_RETURN_IF_ERROR(ran);
    INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(spec.target_exposure_ms * 1e3));
    auto frame = machine.camera->Grab();
    if (!frame.ok()) return frame.status();
    if (spec.target_kind == "cross") {
      return MeasureCrossTargets(*frame, cam, plate.camera_from_plate,
                                 previous->galvo.camera_from_galvo, pitch, spec.cross, &targets,
                                 &report.warnings, found);
    }
    return MeasureTargets(*frame, cam, plate.camera_from_plate, previous->galvo.camera_from_galvo,
                          pitch, find, &targets, &report.warnings, found);
  };
  if (!by_pointer) {
    const Status fresh = machine.person->FreshPlate();
    if (!fresh.ok()) return fail("plate: ", fresh);
  }
  int found_before = 0;
  const Status first = mark_and_measure("targets", [](const Vector3d& p, Vector3d* c) {
    *c = p;
    return true;
  }, &found_before);
  if (!first.ok()) return fail("targets: ", first);
  const int expected = static_cast<int>(targets.size());
  report.metrics["targets_expected"] = expected;
  report.metrics["targets_found"] = found_before;
  log->info("targets: {} of {} found", found_before, expected);

  // 5. Fit on the grid; everything else judged at the check points.
  std::vector<fit::TargetSample> grid, check;
  std::vector<std::string> missing;
  for (const Target& t : targets) {
    if (!t.plate) {
      if (!t.check) missing.push_back("(" + Num(t.nominal.x(), 2) + ", " + Num(t.nominal.y(), 2) + ")");
      continue;
    }
    (t.check ? check : grid).push_back({t.command, *t.plate});
  }
  if (!missing.empty()) {
    std::string list;
    for (size_t i = 0; i < missing.size() && i < 8; ++i) list += (i ? ", " : "") + missing[i];
    if (missing.size() > 8) list += ", ...";
    return finish(false, "targets not found: " + std::to_string(missing.size()) + " of the " +
                             std::to_string(spec.n * spec.n) + " grid targets (" + list +
                             " mm; the warnings say where and why); the grid must be complete");
  }
  // The pointer's spots stand for the targets: through its path measured before (a field
  // calibration with marked targets), the fitted head is still the marking beam's.
  const optics::BeamPath& known = previous->head.pointer;
  const bool known_pointer =
      previous->head.measured && (known.offset_x_mrad != 0.0 || known.offset_y_mrad != 0.0 ||
                                  known.lateral_colour_pct != 0.0);
  const optics::BeamPath target_beam =
      by_pointer && known_pointer ? known : optics::BeamPath{};
  auto physics = fit::HeadFieldFit::Fit(grid, previous->head.model.design, spec.head_fit, target_beam);
  if (!physics.ok()) return finish(false, "fit: " + physics.status().ToString());
  for (const fit::HeadParamFit& p : physics->params()) {
    report.metrics["head_" + p.name] = p.value;
    report.metrics["head_" + p.name + "_stderr"] = p.stderr_value;
  }
  const std::vector<fit::GalvoSample> grid_g = physics->ToGalvo(grid);
  const std::vector<fit::GalvoSample> check_g = physics->ToGalvo(check);
  const std::vector<fit::GalvoSample>& judge = check_g.empty() ? grid_g : check_g;
  if (check_g.empty()) {
    report.warnings.push_back("no check points: the models are judged on the grid they were fitted to");
  }
  const ErrorStats before = Stats(judge);
  report.metrics["check_points"] = static_cast<double>(check_g.size());
  report.metrics["field_error_rms_um_before"] = before.rms_um;
  report.metrics["field_error_max_um_before"] = before.max_um;
  report.metrics["physics_fit_rms_um"] = physics->rms_mm() * 1e3;
  // Seed 003's table: each model's error at the check points (prediction of where the
  // command lands; correcting with it leaves this to first order).
  const auto model_metric = [&](const std::string& key, const fit::FieldModel& m) {
    const fit::ModelError e = fit::PredictionError(m, judge);
    report.metrics["model_" + key + "_rms_um"] = e.rms_mm * 1e3;
    report.metrics["model_" + key + "_max_um"] = e.max_mm * 1e3;
  };
  model_metric("physics", *physics);
  for (int sub = 3; sub <= spec.n; ++sub) {
    if ((spec.n - 1) % (sub - 1) != 0) continue;  // a sub-grid of the marked grid
    const int stride = (spec.n - 1) / (sub - 1);
    std::vector<fit::GalvoSample> nodes;
    for (int j = 0; j < spec.n; j += stride) {
      for (int i = 0; i < spec.n; i += stride) nodes.push_back(grid_g[static_cast<size_t>(j) * spec.n + i]);
    }
    auto m = fit::BilinearFieldModel::Fit(nodes);
    if (m.ok()) model_metric("bilinear_" + std::to_string(sub), *m);
  }
  if (spec.n % 2 == 1) {
    auto q = fit::QuadrantFieldModel::Fit(grid_g, spec.half_size_mm, spec.half_size_mm);
    if (q.ok()) model_metric("quadrant", *q);
  }
  std::optional<fit::PhysicsPlusTableModel> combined;
  if (spec.residual_table) {
    auto both = fit::PhysicsPlusTableModel::Fit(*physics, grid_g);
    if (!both.ok()) return finish(false, "fit: " + both.status().ToString());
    combined = std::move(*both);
    model_metric("physics_table", *combined);
    // The table is kept only where it helps: at the check points it must predict better than
    // the physics alone (a table of pure measurement noise, as pointer spots give, would only
    // add that noise to every correction). Choosing between the two uses the check points,
    // fitting never does.
    if (!check_g.empty() && fit::PredictionError(*combined, check_g).rms_mm >=
                                fit::PredictionError(*physics, check_g).rms_mm) {
      report.warnings.push_back(
          "the residual table does not predict the check points better than the physical head "
          "alone: the correction uses the physics only");
      combined.reset();
    }
  }
  report.metrics["residual_table_used"] = combined ? 1.0 : 0.0;
  const fit::FieldModel& chosen = combined ? static_cast<const fit::FieldModel&>(*combined)
                                           : static_cast<const fit::FieldModel&>(*physics);
  log->info("field: {:.1f} um rms before at {} check points; physics leaves {:.1f} um", before.rms_um,
            check_g.size(), fit::PredictionError(*physics, judge).rms_mm * 1e3);

  // The measured head as the calibration holds it.
  calib::HeadCalibration head = previous->head;
  if (by_pointer && known_pointer) {
    report.warnings.push_back(
        "non-destructive field calibration: the head was measured with the pointer's spots and "
        "taken to the marking beam through the pointer's path measured before (" +
        previous->head.measured_by + "); a change of that path since is not seen");
  } else if (by_pointer) {
    report.warnings.push_back(
        "non-destructive field calibration: the head was measured with the pointer's spots; "
        "marks carry the pointer's misalignment and lateral colour against the marking laser, "
        "which this variant cannot see (mark the spiral targets once to measure the laser and "
        "the pointer's path; later pointer runs then go through it)");
    head.pointer = optics::BeamPath{};  // the fitted head is the pointer's own
  }
  head.measured = true;
  head.measured_by = "field_calibration job " + job.path;
  head.model = physics->head();
  if (!spec.pointer && !by_pointer) {
    report.warnings.push_back(
        "pointer.enabled is false: the pointer's path against the marking beam was not measured; "
        "the calibration keeps the previous one, which belongs to the head as it was before");
  }
  head.residual_mm = combined ? combined->residual().table() : optics::GridTable();
  if (!pointer_spots.empty()) {
    std::vector<fit::GalvoSample> spots;
    for (const PointerSpot& p : pointer_spots) spots.push_back({p.cmd, physics->galvo_from_plate() * p.plate});
    double z_lo = 1e300, z_hi = -1e300;
    for (const fit::GalvoSample& g : spots) {
      z_lo = std::min(z_lo, g.cmd.z());
      z_hi = std::max(z_hi, g.cmd.z());
    }
    const bool fit_e = z_hi - z_lo >= 2.0;
    auto path = fit::FitBeamPath(head.model, spots, fit_e);
    if (!path.ok()) return finish(false, "pointer: " + path.status().ToString());
    head.pointer = path->path;
    if (fit_e) {
      // The same mirrors carry both beams.
      head.model.built.mirror_separation_mm = path->mirror_separation_mm;
      report.metrics["head_mirror_separation_mm"] = path->mirror_separation_mm;
      report.metrics["head_mirror_separation_mm_stderr"] = path->stderr_mirror_separation_mm;
    } else {
      report.warnings.push_back("the pointer's spots lie on one plane: the mirror separation "
                                "stays the design's (pointer.stage_z_mm lists one height)");
    }
    report.metrics["pointer_offset_x_mrad"] = path->path.offset_x_mrad;
    report.metrics["pointer_offset_y_mrad"] = path->path.offset_y_mrad;
    report.metrics["pointer_lateral_colour_pct"] = path->path.lateral_colour_pct;
    report.metrics["pointer_fit_rms_um"] = path->rms_mm * 1e3;
    report.metrics["pointer_spots"] = static_cast<double>(spots.size());
  }
  // Every corrected command of the field must be one the head can take.
  const CommandMap corrected = [&](const Vector3d& p, Vector3d* c) {
    return chosen.CommandFor(p, c);
  };
  {
    // Within the grid (and its targets) every correction must be one the head can take.
    for (int j = 0; j <= 40; ++j) {
      for (int i = 0; i <= 40; ++i) {
        const double x = -reach + reach * i / 20.0, y = -reach + reach * j / 20.0;
        Vector3d c;
        const double lim = head_info.field_half_size_mm;
        if (!corrected({x, y, 0.0}, &c) || (lim > 0 && (std::abs(c.x()) > lim || std::abs(c.y()) > lim))) {
          return finish(false, "the correction would send (" + Num(x, 2) + ", " + Num(y, 2) +
                                   ") mm outside the head's range (+-" + Num(lim, 2) +
                                   " mm): reduce grid.half_size_mm");
        }
      }
    }
    // The tables cover the head's whole field. Beyond the grid the physics extrapolates; a node
    // it cannot bring within the head's range takes the correction at the grid's edge.
    const double half = head_info.field_half_size_mm > 0 ? head_info.field_half_size_mm : reach;
    int clamped = 0;
    bool counting = true;  // the clamped nodes of correction.csv (field.cor's are the same field)
    const auto offset_at = [&](double x, double y) {
      Vector3d c;
      if (corrected({x, y, 0.0}, &c) && std::abs(c.x()) <= half && std::abs(c.y()) <= half) {
        return Vector2d(c.head<2>() - Vector2d(x, y));
      }
      if (counting) ++clamped;
      const double cx = std::clamp(x, -reach, reach), cy = std::clamp(y, -reach, reach);
      return corrected({cx, cy, 0.0}, &c) ? Vector2d(c.head<2>() - Vector2d(cx, cy)) : Vector2d(0, 0);
    };
    const int m = spec.correction_nodes;
    std::vector<double> xs(m), ys(m);
    std::vector<Vector2d> offsets;
    for (int i = 0; i < m; ++i) xs[i] = ys[i] = -half + 2.0 * half * i / (m - 1);
    for (double y : ys) {
      for (double x : xs) offsets.push_back(offset_at(x, y));
    }
    auto table = optics::GridTable::Make(xs, ys, offsets);
    if (!table.ok()) return finish(false, table.status().ToString(), StatusCode::kInternal);
    const pattern::CorrectionTable correction(*table);
    if (WriteFileAtomically((dir / "correction.csv").string(), correction.ToCsv()).ok()) {
      report.artifacts["correction"] = "correction.csv";
    }
    counting = false;
    if (head_info.field_half_size_mm > 0) {
      // The whole table a board driving this head needs (docs/calibration.md, "field.cor"):
      // the measured correction composed with what the controller does now, in the documented
      // convention for the board's axes.
      hw::lmc::BoardOptions board;
      board.lens_mm = head_info.table_field_mm > 0 ? head_info.table_field_mm
                                                   : 2.0 * head_info.field_half_size_mm;
      board.swap_xy = head_info.table_swap_xy;
      board.flip_x = head_info.table_flip_x;
      board.flip_y = head_info.table_flip_y;
      const auto cor = hw::lmc::BoardTableFromDrive(
          ControllerDrive(*machine.scanner, previous->head.model.design, offset_at), board,
          hw::lmc::CorFormat::kJcz2);
      if (hw::lmc::WriteCor((dir / "field.cor").string(), cor).ok()) {
        report.artifacts["field_cor"] = "field.cor";
      }
    }
    if (clamped > 0) {
      report.warnings.push_back(
          std::to_string(clamped) + " nodes of correction.csv / field.cor beyond the measured "
          "grid lie where the corrected command would leave the head's range: they take the "
          "correction at the grid's edge");
    }
  }
  if (WriteFieldCsv(targets, physics->galvo_from_plate(), (dir / "field.csv").string()).ok()) {
    report.artifacts["field"] = "field.csv";
  }
  const auto arrows = [&](const std::string& title, double magnification, const std::string& file) {
    FieldArrows a;
    a.title = title;
    a.magnification = magnification;
    for (const Target& t : targets) {
      if (!t.plate) continue;
      const Vector2d m = physics->galvo_from_plate() * *t.plate;
      a.x_mm.push_back(t.nominal.x());
      a.y_mm.push_back(t.nominal.y());
      a.dx_mm.push_back(m.x() - t.nominal.x());
      a.dy_mm.push_back(m.y() - t.nominal.y());
      a.check.push_back(t.check);
    }
    return SaveFieldArrowsPng(a, (dir / file).string());
  };
  if (arrows("field error before correction, " + Num(before.rms_um, 1) + " um rms at the check points",
             0.0, "field_before.png").ok()) {
    report.artifacts["field_before"] = "field_before.png";
  }

  // 6. The second pass through the correction, measured in the same frame.
  if (spec.verify) {
    if (cancelled()) return finish(false, "cancelled", StatusCode::kCancelled);
    if (!by_pointer) {
      const Status again = machine.person->FreshPlate();
      if (!again.ok()) return fail("second pass: ", again);
    }
    std::vector<bool> found_first;
    for (const Target& t : targets) found_first.push_back(t.plate.has_value());
    int found_after = 0;
    const Status second = mark_and_measure("corrected targets", corrected, &found_after);
    if (!second.ok()) return fail("second pass: ", second);
    report.metrics["targets_found_after"] = found_after;
    // Before and after on the same targets: one the correction sent off (or spoilt) is a
    // failure, never a point quietly left out of the after figure.
    std::string lost;
    int n_lost = 0;
    for (size_t k = 0; k < targets.size(); ++k) {
      if (found_first[k] && !targets[k].plate) {
        if (n_lost++ < 6) {
          lost += std::string(lost.empty() ? "" : ", ") + "(" + Num(targets[k].nominal.x(), 2) +
                  ", " + Num(targets[k].nominal.y(), 2) + ")";
        }
      }
    }
    if (n_lost > 0) {
      return finish(false, "second pass: " + std::to_string(n_lost) +
                               " targets measured in the first pass were not found through the "
                               "correction (" + lost + (n_lost > 6 ? ", ..." : "") +
                               " mm; the warnings say why); the calibration was not saved");
    }
    std::vector<fit::GalvoSample> after_check, after_grid;
    for (const Target& t : targets) {
      if (!t.plate) continue;
      // Asked for the nominal position: the error is measured against it.
      const fit::GalvoSample s{{t.nominal.x(), t.nominal.y(), 0.0},
                               physics->galvo_from_plate() * *t.plate};
      (t.check ? after_check : after_grid).push_back(s);
    }
    const ErrorStats after = Stats(after_check.empty() ? after_grid : after_check);
    report.metrics["field_error_rms_um_after"] = after.rms_um;
    report.metrics["field_error_max_um_after"] = after.max_um;
    report.metrics["field_error_rms_um_after_grid"] = Stats(after_grid).rms_um;
    report.metrics["distortion_removed_pct"] =
        before.rms_um > 0 ? 100.0 * (1.0 - after.rms_um / before.rms_um) : 0.0;
    if (arrows("field error after correction, " + Num(after.rms_um, 1) + " um rms at the check points",
               0.0, "field_after.png").ok()) {
      report.artifacts["field_after"] = "field_after.png";
    }
    log->info("field: {:.1f} um rms after ({:.1f} % removed)", after.rms_um,
              report.metrics["distortion_removed_pct"]);
    // On a head already within the bar, before and after are both the measurement's own
    // scatter (~2 um): "less than before" is then a coin toss, and only the bar applies.
    const bool must_improve = before.rms_um > spec.max_error_rms_um_after;
    if (after.rms_um > spec.max_error_rms_um_after || (must_improve && after.rms_um >= before.rms_um)) {
      return finish(false, "second pass: the corrected field measures " + Num(after.rms_um, 1) +
                               " um rms at the check points (before: " + Num(before.rms_um, 1) +
                               " um; accepted: up to " + Num(spec.max_error_rms_um_after, 1) +
                               " um, and less than before when before was above that); the "
                               "calibration was not saved. Check "
                               "field_after.png: a pattern means the plate or camera moved");
    }
  }

  // 7. The machine calibration: the measured head, and the camera's pose in the galvo frame
  // through the plate (plate z = galvo z: the plate's top is the focal plane at stage 0).
  calib::CalibrationSet set = *previous;
  set.head = head;
  set.produced_by = previous->produced_by + "; field_calibration job " + job.path;
  set.created = report.started;
  Eigen::Isometry3d plate_from_galvo = Eigen::Isometry3d::Identity();
  const Eigen::Isometry2d pg = physics->galvo_from_plate().inverse();
  plate_from_galvo.linear().topLeftCorner<2, 2>() = pg.linear();
  plate_from_galvo.translation().head<2>() = pg.translation();
  set.galvo.camera_from_galvo = plate.camera_from_plate * plate_from_galvo;
  const Status saved = SaveMeasuredCalibration(
      set, OutputPath(spec.output_path, "output.calibration", options, &report.warnings),
      options.out_dir, &report);
  if (!saved.ok()) return fail("", saved);
  return finish(true, "");
}

}  // namespace insitu::job
