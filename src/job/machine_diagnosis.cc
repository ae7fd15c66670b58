#include "job/machine_diagnosis.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <random>
#include <tuple>

#include "insitu/core/file.h"
#include "insitu/core/log.h"
#include "insitu/fit/group_model.h"
#include "insitu/geometry/triangulation.h"
#include "insitu/job/scan.h"
#include "insitu/vision/canvas.h"
#include "insitu/vision/image.h"
#include "insitu/vision/targets.h"
#include "job/output_path.h"
#include "job/progress.h"
#include "job/scan_job.h"

namespace insitu::job {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

struct DiagnoseMachineSpec {
  ScanJobSpec scan;
  std::vector<double> stage_z_mm{0.0};  // one pass per height
  double bin_mm = 2.0;                  // points along a line averaged over this length
  fit::GroupSelectionOptions selection;
  // The residuals of the machine as calibrated (a scan right after calibrating): what the
  // calibration itself leaves is not a change of the machine.
  std::string baseline_path;
  bool record_baseline = false;
  // Each pass focuses on the gauge where the stage took it (focus z = scan focus + stage z), as
  // a 3D head works; then the focus shifter's scale shows between the passes.
  bool refocus = true;
  // The pointer parked on the plate beside the gauge at each pass, at every (x, y) of these
  // (galvo mm, focused on the plate): where the head puts the beam against where the camera
  // sees it, along the lines too, which the gauge's heights cannot show (a Y mirror's zero).
  // Either list empty: no spots.
  std::vector<double> spot_x_mm{-40.0, -25.0, 25.0, 40.0};
  std::vector<double> spot_y_mm{-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0};
  double spot_exposure_ms = 0.5;
  // The gauge stands where it stood for the baseline (a fixture on the stage): its ends along
  // the lines are then a mark in the world, and tell the camera's shift along the lines from
  // the mirrors'. false: a gauge placed anew; its ends are not used.
  bool gauge_fixed = true;
};

Status ReadSpec(const LoadedJob& job, DiagnoseMachineSpec* s, hw::MachineConfig* machine) {
  INSITU_RETURN_IF_ERROR(ReadScanJob(job, &s->scan, machine, [&](ConfigReader& r) {
    ReadArtifact(r, &s->scan);
    if (r.Has("diagnosis")) {
      ConfigReader& d = r.Section("diagnosis");
      d.Read("stage_z_mm", &s->stage_z_mm);
      d.Read("bin_mm", &s->bin_mm);
      d.Read("folds", &s->selection.folds);
      d.Read("min_delta_bic", &s->selection.min_delta_bic);
      d.Read("min_cv_improvement", &s->selection.min_cv_improvement);
      std::string baseline;
      d.Read("baseline", &baseline);
      if (!baseline.empty()) s->baseline_path = ResolvePath(job.folder, baseline);
      d.Read("record_baseline", &s->record_baseline);
      d.Read("refocus", &s->refocus);
      d.Read("spot_x_mm", &s->spot_x_mm);
      d.Read("spot_y_mm", &s->spot_y_mm);
      d.Read("spot_exposure_ms", &s->spot_exposure_ms);
      d.Read("gauge_fixed", &s->gauge_fixed);
      if (d.ok() && !(s->spot_exposure_ms > 0)) d.Fail("spot_exposure_ms", "must be > 0");
      for (const auto* list : {&s->spot_x_mm, &s->spot_y_mm}) {
        std::vector<double> sorted = *list;
        std::sort(sorted.begin(), sorted.end());
        if (d.ok() && std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
          d.Fail(list == &s->spot_x_mm ? "spot_x_mm" : "spot_y_mm", "lists a value twice");
        }
      }
      if (d.ok() && s->stage_z_mm.empty()) d.Fail("stage_z_mm", "must list at least one height");
      if (d.ok() && !(s->bin_mm > 0)) d.Fail("bin_mm", "must be > 0");
      if (d.ok()) d.FailFromValidate(s->selection.Validate());
    }
  }));
  if (s->scan.artifact != "step_gauge") {
    return InvalidArgument(job.path +
                           ": a diagnose_machine job needs an artifact: of kind step_gauge");
  }
  // A spot must land on the plate: one on the gauge (2 mm around it) would be intersected with
  // the plate's plane at the wrong height.
  const inspect::StepGaugeSpec& g = s->scan.gauge;
  const double half_x = 0.5 * g.step_width_mm * g.heights_mm.size() + 2.0;
  const double half_y = 0.5 * g.length_mm + 2.0;
  for (double x : s->spot_x_mm) {
    for (double y : s->spot_y_mm) {
      if (std::abs(x - g.center_x_mm) < half_x && std::abs(y - g.center_y_mm) < half_y) {
        char text[200];
        std::snprintf(text, sizeof text,
                      ": diagnosis.spot_x_mm, spot_y_mm: the spot at (%g, %g) mm lies on the "
                      "gauge (or within 2 mm of it): spots go on the plate beside it",
                      x, y);
        return InvalidArgument(job.path + text);
      }
    }
  }
  if (s->scan.method != 1) {
    return InvalidArgument(job.path + ": reconstruction.method must be 1 (camera and light plane)");
  }
  if (s->baseline_path.empty()) {
    // Beside the calibration it belongs to.
    s->baseline_path = (std::filesystem::path(s->scan.machine.calibration_path).parent_path() /
                        "diagnose_baseline.csv")
                           .string();
  }
  return Status::Ok();
}

// What an observation measures (its residual, mm):
//   kHeight: a stripe centre averaged over a bin along its line on a step's top: its height
//            less the step's;
//   kEnd:    where a line leaves a step's top at one of the gauge's ends (`side` -1: y low,
//            +1: y high): its y less the end's;
//   kSpotX, kSpotY: the pointer parked at `command` on the plate (`line` numbers the spot in
//            its pass): where the camera sees it less where the head puts it, along x or y.
enum Kind { kHeight, kEnd, kSpotX, kSpotY };

struct Observation {
  Vector2d pixel;  // full sensor
  int pass = 0, line = 0, step = 0, bin = 0;
  double baseline_mm = 0.0;  // its residual when the machine was as calibrated
  Kind kind = kHeight;
  int side = 0;
  Vector2d command = Vector2d::Zero();
};

bool OnLine(const Observation& o) { return o.kind == kHeight || o.kind == kEnd; }

// An observation's place, as the baseline file names it.
std::string KeyOf(double stage_z_mm, double line_x_mm, int step, int bin) {
  char b[96];
  std::snprintf(b, sizeof b, "%.3f,%.3f,%d,%d", stage_z_mm, line_x_mm, step, bin);
  return b;
}

struct Pass {
  double stage_z_mm = 0.0;
  double focus_z_mm = 0.0;                           // the pass's commanded focus
  std::vector<std::pair<Vector3d, Vector3d>> lines;  // commanded ends
};

enum Group {
  kCameraPose,
  kCameraDistortion,
  kHeadScale,
  kGalvoOffset,
  kLightPlane,
  kStageScale,
  kFocusScale
};

// stage_scale needs two stage heights; focus_scale two focus heights (the head refocused on the
// gauge at each), and comes only with stage_scale.
std::vector<fit::ParameterGroup> Candidates(bool two_heights, bool two_focus = false) {
  std::vector<fit::ParameterGroup> c = {
      {"camera_pose",
       "the camera moved since calibration (bumped, remounted)",
       {"rx_mrad", "ry_mrad", "rz_mrad", "tx_mm", "ty_mm", "tz_mm"},
       {0.2, 0.2, 0.2, 0.1, 0.1, 0.1}},
      {"camera_distortion",
       "the camera lens's distortion changed (refocused, another lens)",
       {"dk1", "dk2"},
       {1e-3, 1e-3}},
      {"head_scale",
       "the field's size changed: objective focal length or galvo gain",
       {"s_permille"},
       {0.5}},
      {"galvo_offset", "the field moved: mirror zero offsets", {"ox_mm", "oy_mm"}, {0.05, 0.05}},
      {"light_plane",
       "the pointer's light planes lean otherwise: a turn about the line (mirror axis) and a "
       "lean growing with the field (the exit pupil's height)",
       {"tilt_mrad", "pupil_mm"},
       {0.5, 5.0}},
  };
  if (two_heights) {
    c.push_back({"stage_scale", "the stage moves differ from its commands", {"s_permille"}, {0.5}});
    if (two_focus) {
      c.push_back({"focus_scale",
                   "the field's size changes with the dynamic focus otherwise than calibrated "
                   "(the focus shifter's travel): x grows by c z x",
                   {"c_permille_per_mm"},
                   {0.1}});
    }
  }
  return c;
}

class CellModel : public fit::GroupModel {
 public:
  // `groups`: the candidates in Group order, as fit::DiagnoseGroups lays out theta.
  CellModel(const calib::CalibrationSet& cal, const inspect::StepGaugeSpec& gauge,
            std::vector<Pass> passes, std::vector<Observation> obs,
            const std::vector<fit::ParameterGroup>& groups)
      : cal_(cal),
        gauge_(gauge),
        passes_(std::move(passes)),
        obs_(std::move(obs)),
        two_heights_(static_cast<int>(groups.size()) > kStageScale),
        has_focus_(static_cast<int>(groups.size()) > kFocusScale) {
    begin_.push_back(0);
    for (const fit::ParameterGroup& g : groups) {
      begin_.push_back(begin_.back() + static_cast<int>(g.params.size()));
    }
    std::vector<Vector2d> px;
    for (const Observation& o : obs_) px.push_back(o.pixel);
    normalized_ = cal_.camera.Undistort(px);
  }

  int units() const override { return static_cast<int>(obs_.size()); }
  // Channels: the gauge (heights and ends: what the scan measures) and the pointer's spots.
  int channels() const override { return 2; }
  int channel(int unit) const override { return OnLine(obs_[unit]) ? 0 : 1; }
  // A line's heights and ends are held out together; each spot on its own.
  int fold_key(int unit) const override {
    const Observation& o = obs_[unit];
    return o.pass * 100000 + (OnLine(o) ? o.line : 50000 + o.line);
  }

  bool Residuals(const std::vector<double>& theta, const std::vector<int>& use,
                 std::vector<double>* residuals) const override {
    residuals->assign(use.size(), 0.0);
    std::vector<Vector3d> points;
    if (!Points(theta, use, &points)) return false;
    const double stage_scale = two_heights_ ? theta[Begin(kStageScale)] * 1e-3 : 0.0;
    const double scale = 1.0 + theta[Begin(kHeadScale)] * 1e-3;
    const Vector2d shift(theta[Begin(kGalvoOffset)], theta[Begin(kGalvoOffset) + 1]);
    const double focus = has_focus_ ? theta[Begin(kFocusScale)] * 1e-3 : 0.0;
    for (size_t k = 0; k < use.size(); ++k) {
      const Observation& o = obs_[use[k]];
      const double z_stage = passes_[o.pass].stage_z_mm * (1.0 + stage_scale);
      double r = 0.0;
      switch (o.kind) {
        case kHeight:
          r = points[k].z() - (gauge_.base_z_mm + gauge_.heights_mm[o.step] + z_stage);
          break;
        case kEnd:
          r = points[k].y() - (gauge_.center_y_mm + 0.5 * o.side * gauge_.length_mm);
          break;
        case kSpotX:
        case kSpotY: {
          // The spot is focused where the stage says the plate is (commanded at the stage's
          // height z). The controller aims along the chief ray from the exit pupil as
          // calibrated (H0 above the field): the field's command x0 = x H0 / (H0 - z). The
          // beam leaves the pupil where it really is (H, light_plane's pupil term) and meets
          // the plate where it really is (z_stage): x0 (H - z_stage) / H. Both differ from the
          // commands' only with a pupil moved or a stage screw off.
          const double z = passes_[o.pass].stage_z_mm;
          const double h0 = NominalPupilHeight(), h = PupilHeight(theta);
          const double lean = h0 * (h - z_stage) / ((h0 - z) * h);
          const Vector2d landed = (scale + focus * z) * lean * o.command + shift;
          const int axis = o.kind == kSpotX ? 0 : 1;
          r = points[k][axis] - landed[axis];
          break;
        }
      }
      (*residuals)[k] = r - o.baseline_mm;
    }
    return true;
  }

  // The exit pupil's height above the field as calibrated, and as theta has it (light_plane's
  // pupil term).
  double NominalPupilHeight() const {
    return cal_.head.measured ? cal_.head.model.built.exit_pupil_height_mm
                              : cal_.galvo.pivot_height_mm;
  }
  double PupilHeight(const std::vector<double>& theta) const {
    return NominalPupilHeight() + theta[Begin(kLightPlane) + 1];
  }

  // The points of `use` in the galvo frame for parameters theta.
  bool Points(const std::vector<double>& theta, const std::vector<int>& use,
              std::vector<Vector3d>* out) const {
    // Rays: the camera's pose and its distortion as theta has them.
    const double* pose = &theta[Begin(kCameraPose)];
    const double* dist = &theta[Begin(kCameraDistortion)];
    const Eigen::Isometry3d galvo_from_camera = cal_.galvo.camera_from_galvo.inverse();
    const Eigen::Matrix3d turn = (Eigen::AngleAxisd(pose[2] * 1e-3, Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(pose[1] * 1e-3, Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(pose[0] * 1e-3, Vector3d::UnitX()))
                                     .toRotationMatrix();
    const Vector3d origin = galvo_from_camera.translation() + Vector3d(pose[3], pose[4], pose[5]);
    const Eigen::Matrix3d to_galvo = turn * galvo_from_camera.linear();
    std::vector<Vector2d> normalized;
    if (dist[0] != 0.0 || dist[1] != 0.0) {
      calib::CameraIntrinsics cam = cal_.camera;
      cam.k1 += dist[0];
      cam.k2 += dist[1];
      std::vector<Vector2d> px;
      for (int i : use) px.push_back(obs_[i].pixel);
      normalized = cam.Undistort(px);
    } else {
      for (int i : use) normalized.push_back(normalized_[i]);
    }
    // Light planes (galvo frame) for the lines used, as theta moves the field.
    const double scale = 1.0 + theta[Begin(kHeadScale)] * 1e-3;
    const Vector3d shift(theta[Begin(kGalvoOffset)], theta[Begin(kGalvoOffset) + 1], 0.0);
    const double tilt = theta[Begin(kLightPlane)] * 1e-3;
    const double pupil = theta[Begin(kLightPlane) + 1];  // mm of exit pupil height
    // Chief rays lean by x / L from a pupil L above the field; from L + dL by x dL / L^2 less.
    const double height = NominalPupilHeight();
    const double stage_scale = two_heights_ ? theta[Begin(kStageScale)] * 1e-3 : 0.0;
    std::map<std::pair<int, int>, Eigen::Vector4d> planes;
    out->resize(use.size());
    for (size_t k = 0; k < use.size(); ++k) {
      const Observation& o = obs_[use[k]];
      if (!OnLine(o)) {
        // A spot on the plate's top, which rides on the stage (galvo z = stage z).
        const Vector3d dir = to_galvo * Vector3d(normalized[k].x(), normalized[k].y(), 1.0);
        if (std::abs(dir.z()) < 1e-12) return false;
        const double z = passes_[o.pass].stage_z_mm * (1.0 + stage_scale);
        (*out)[k] = origin + (z - origin.z()) / dir.z() * dir;
        continue;
      }
      const auto key = std::make_pair(o.pass, o.line);
      auto it = planes.find(key);
      if (it == planes.end()) {
        const auto& [from, to] = passes_[o.pass].lines[o.line];
        Vector3d a = from, b = to;
        // focus_scale: u += c z x, v += c z y at the line's focus height z.
        const double focus = has_focus_ ? theta[Begin(kFocusScale)] * 1e-3 : 0.0;
        a.head<2>() = (scale + focus * a.z()) * a.head<2>() + shift.head<2>();
        b.head<2>() = (scale + focus * b.z()) * b.head<2>() + shift.head<2>();
        const geometry::PlaneInCamera p =
            geometry::LineLightPlane(cal_, a, b, 20.0, Eigen::Isometry3d::Identity());
        Vector3d n = p.coeffs.head<3>();
        double d = p.coeffs[3];
        // The plane's normal ~ (L, 0, x): a pupil dL higher turns it by +x dL / L^2 about +y
        // (L: the pupil's height above the focal plane; the pass's own focus shift changes it
        // by ~1 %, left out).
        const double lean = tilt + a.x() * pupil / (height * height);
        if (lean != 0.0) {
          // Turned about the line (along y through the line's commanded position, at its focus z).
          const Vector3d on(a.x(), 0.0, a.z());
          const Vector3d anchor = on - n * ((n.dot(on) + d) / n.squaredNorm());
          n = Eigen::AngleAxisd(lean, Vector3d::UnitY()) * n;
          d = -n.dot(anchor);
        }
        it = planes.emplace(key, Eigen::Vector4d(n.x(), n.y(), n.z(), d)).first;
      }
      const Eigen::Vector4d& pl = it->second;
      const Vector3d dir = to_galvo * Vector3d(normalized[k].x(), normalized[k].y(), 1.0);
      const double denom = pl.head<3>().dot(dir);
      if (std::abs(denom) < 1e-12) return false;
      const double t = -(pl.head<3>().dot(origin) + pl[3]) / denom;
      (*out)[k] = origin + t * dir;
    }
    return true;
  }

  // The gauge placement moves which step a point is on only at the edges, which the margin
  // keeps out; each point's step is fixed once (at theta = 0), so the residuals are smooth.
  static int StepOf(const inspect::StepGaugeSpec& g, const Vector2d& xy) {
    if (std::abs(xy.y() - g.center_y_mm) > 0.5 * g.length_mm - g.edge_margin_mm) return -1;
    return StepAtX(g, xy.x());
  }
  // The step whose top spans galvo x within its margins, at any y; -1: none.
  static int StepAtX(const inspect::StepGaugeSpec& g, double x_mm) {
    const double half_width = 0.5 * g.step_width_mm * g.heights_mm.size();
    const double x = x_mm - g.center_x_mm + half_width;
    const int k = static_cast<int>(std::floor(x / g.step_width_mm));
    if (k < 0 || k >= static_cast<int>(g.heights_mm.size())) return -1;
    const double in = x - k * g.step_width_mm;
    if (in < g.edge_margin_mm || in > g.step_width_mm - g.edge_margin_mm) return -1;
    return k;
  }

  int Begin(Group g) const { return begin_[g]; }
  int parameters() const { return begin_.back(); }

 private:
  const calib::CalibrationSet& cal_;
  inspect::StepGaugeSpec gauge_;
  std::vector<Pass> passes_;
  std::vector<Observation> obs_;
  std::vector<Vector2d> normalized_;
  bool two_heights_, has_focus_;
  std::vector<int> begin_;  // group g's parameters: theta[begin_[g] .. begin_[g + 1])
};

nlohmann::ordered_json GroupJson(const fit::GroupReport& g) {
  nlohmann::ordered_json params = nlohmann::ordered_json::object();
  nlohmann::ordered_json errs = nlohmann::ordered_json::object();
  for (size_t k = 0; k < g.params.size(); ++k) {
    params[g.params[k]] = g.values[k];
    if (std::isfinite(g.stderrs[k])) {
      errs[g.params[k]] = g.stderrs[k];
    } else {
      errs[g.params[k]] = nullptr;
    }
  }
  nlohmann::ordered_json e;
  e["name"] = g.name;
  e["meaning"] = g.meaning;
  e["params"] = params;
  e["stderr"] = errs;
  e["delta_bic"] = g.delta_bic;
  e["cv_rms_mm"] = g.cv_rms;
  return e;
}

// Residual heights over the gauge, before and after, as coloured dots (blue low, red high,
// the same scale in both panels).
Status SaveResidualMap(const std::vector<Vector3d>& points, const std::vector<double>& before,
                       const std::vector<double>& after, const std::string& title_after,
                       const std::string& path) {
  const int w = 600, h = 600, pad = 50;
  vision::Canvas img(2 * w + 20, h + 40);
  Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (const Vector3d& p : points) {
    lo = lo.cwiseMin(p.head<2>());
    hi = hi.cwiseMax(p.head<2>());
  }
  double span = 0;
  for (double r : before) span = std::max(span, std::abs(r));
  if (!(span > 0)) span = 1e-3;
  const double sx = (w - 2 * pad) / std::max(1e-6, hi.x() - lo.x());
  const double sy = (h - 2 * pad) / std::max(1e-6, hi.y() - lo.y());
  const auto panel = [&](int x0, const std::vector<double>& r, const std::string& title) {
    img.Rectangle(x0, 0, w, h, {.rgb = 0xC8C8C8});
    for (size_t k = 0; k < points.size() && k < r.size(); ++k) {
      const double t = std::clamp(r[k] / span, -1.0, 1.0);
      const int c = t >= 0 ? vision::RgbOf(255, 255 * (1 - t), 255 * (1 - t))
                           : vision::RgbOf(255 * (1 + t), 255 * (1 + t), 255);
      const Vector2d q(x0 + pad + static_cast<int>((points[k].x() - lo.x()) * sx),
                       h - pad - static_cast<int>((points[k].y() - lo.y()) * sy));
      img.Circle(q, 3, {.rgb = c, .thickness = vision::kFill, .smooth = true});
    }
    double rms = 0;
    for (double v : r) rms += v * v;
    rms = r.empty() ? 0 : std::sqrt(rms / r.size());
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s: rms %.4f mm", title.c_str(), rms);
    img.Text(buf, Vector2d(x0 + 10, 24), 0.5, {.rgb = 0x000000, .smooth = true});
  };
  panel(0, before, "height residual, as calibrated");
  panel(w + 20, after, title_after);
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "x right, y up over the gauge; colour: -%.3f mm (blue) .. +%.3f mm (red)", span,
                span);
  img.Text(buf, Vector2d(10, h + 28), 0.5, {.rgb = 0x000000, .smooth = true});
  return img.WritePng(path);
}

// The baseline's record of how its passes were focused.
std::string RefocusLine(bool refocus) {
  return std::string("# refocus: ") + (refocus ? "true" : "false");
}

// The baseline's record of how its frames were made: the stripe centres of a scan with the
// room's light subtracted and the line swept evenly differ from one without by a fraction of a
// pixel where light falls across the stripe, a change of the heights the size of their noise.
std::string FramesLine(const ScanOptions& scan) {
  return "# frames: room light subtracted over " + std::to_string(scan.background_frames) +
         " frames, line swept in whole periods";
}

constexpr double kAlpha = 0.01;  // false-alarm rate of the structure test (both channels)
constexpr int kPermutations = 999;

std::string Join(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// Structure in residuals whose neighbours are independent draws of the noise: neighbouring
// bins of a scan line (speckle decorrelates within a bin) or neighbouring spots of a column.
// Half the mean squared difference of neighbours is the noise variance, free of any smooth
// structure (von Neumann); what the residuals hold beyond it is structure. Its significance:
// the neighbours' summed products against the same sum for residuals shuffled among the
// observations (one-sided: a structure smoother than the spacing makes neighbours alike).
struct Structure {
  double rho = 0.0;           // lag-one correlation over neighbours
  double noise_mm = 0.0;      // from neighbours' differences
  double structure_mm = 0.0;  // rms beyond the noise
  double p = 1.0;
  std::string where;    // the observations holding the largest residuals
  bool tested = false;  // enough neighbours (10 pairs) to say anything
  // Significant at the share of kAlpha of one of `channels` tested, and at least half the noise.
  bool Flagged(int channels) const {
    return tested && p < kAlpha / std::max(1, channels) && structure_mm >= 0.5 * noise_mm;
  }
};

// `pairs` index neighbours in `r`; fewer than 10 pairs say nothing.
Structure PairStructure(const std::vector<double>& r,
                        const std::vector<std::pair<int, int>>& pairs) {
  Structure s;
  if (pairs.size() < 10) return s;
  s.tested = true;
  double prod = 0, diff2 = 0, sq = 0;
  for (const auto& [i, j] : pairs) {
    prod += r[i] * r[j];
    diff2 += (r[i] - r[j]) * (r[i] - r[j]);
    sq += 0.5 * (r[i] * r[i] + r[j] * r[j]);
  }
  const double n = static_cast<double>(pairs.size());
  s.rho = sq > 0 ? prod / sq : 0.0;
  const double noise2 = 0.5 * diff2 / n;
  s.noise_mm = std::sqrt(noise2);
  s.structure_mm = std::sqrt(std::max(0.0, sq / n - noise2));
  std::vector<double> shuffled = r;
  std::mt19937_64 rng(0x5bd1e995ull);
  int above = 0;
  for (int t = 0; t < kPermutations; ++t) {
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    double q = 0;
    for (const auto& [i, j] : pairs) q += shuffled[i] * shuffled[j];
    above += q >= prod;
  }
  s.p = (1.0 + above) / (1.0 + kPermutations);
  return s;
}

// PairStructure of `r` over `pairs`, with `where` naming the tenth of the residuals largest in
// size (at least one) by the span of their places: extent(k) = (x_lo, x_hi, y_lo, y_hi), mm.
Structure Located(const std::vector<double>& r, const std::vector<std::pair<int, int>>& pairs,
                  const std::function<Eigen::Vector4d(int)>& extent, const char* what,
                  const char* at) {
  Structure s = PairStructure(r, pairs);
  if (!s.tested) return s;
  std::vector<int> top(r.size());
  std::iota(top.begin(), top.end(), 0);
  std::sort(top.begin(), top.end(), [&](int a, int b) { return std::abs(r[a]) > std::abs(r[b]); });
  top.resize(std::max<size_t>(1, r.size() / 10));
  Eigen::Vector4d span(1e300, -1e300, 1e300, -1e300);
  for (int k : top) {
    const Eigen::Vector4d e = extent(k);
    span = Eigen::Vector4d(std::min(span[0], e[0]), std::max(span[1], e[1]),
                           std::min(span[2], e[2]), std::max(span[3], e[3]));
  }
  char b[240];
  std::snprintf(b, sizeof b,
                "%s: %.1f um rms beyond %.1f um of noise, largest (%.1f um and below) %s x "
                "%.1f..%.1f mm, y %.1f..%.1f mm",
                what, s.structure_mm * 1e3, s.noise_mm * 1e3, std::abs(r[top[0]]) * 1e3, at,
                span[0], span[1], span[2], span[3]);
  s.where = b;
  return s;
}

// The heights' bins along their lines (the gauge's ends are not bins along a line).
Structure LineStructure(const std::vector<Observation>& observed,
                        const std::vector<double>& residuals, const std::vector<Pass>& passes,
                        double bin_mm) {
  std::vector<Observation> obs;
  std::vector<double> r;
  for (size_t k = 0; k < observed.size() && k < residuals.size(); ++k) {
    if (observed[k].kind != kHeight) continue;
    obs.push_back(observed[k]);
    r.push_back(residuals[k]);
  }
  std::vector<std::pair<int, int>> pairs;
  for (size_t k = 0; k + 1 < obs.size(); ++k) {
    const Observation &a = obs[k], &b = obs[k + 1];
    if (a.pass == b.pass && a.line == b.line && a.step == b.step && b.bin == a.bin + 1) {
      pairs.push_back({static_cast<int>(k), static_cast<int>(k + 1)});
    }
  }
  const auto extent = [&](int k) {
    const Observation& o = obs[k];
    const double x = passes[o.pass].lines[o.line].first.x();
    return Eigen::Vector4d(x, x, o.bin * bin_mm, (o.bin + 1) * bin_mm);
  };
  return Located(r, pairs, extent, "heights", "on lines at");
}

// The pointer's spots along the columns of the grid they were parked on (each pass, each axis,
// each x: neighbours in y). A plate no longer flat moves them smoothly, speckle by chance.
Structure SpotStructure(const std::vector<Observation>& observed,
                        const std::vector<double>& residuals) {
  std::vector<int> spots;
  for (size_t k = 0; k < observed.size() && k < residuals.size(); ++k) {
    if (!OnLine(observed[k])) spots.push_back(static_cast<int>(k));
  }
  const auto column = [&](int k) {
    const Observation& o = observed[k];
    return std::make_tuple(o.pass, static_cast<int>(o.kind), o.command.x());
  };
  std::sort(spots.begin(), spots.end(), [&](int a, int b) {
    return std::make_pair(column(a), observed[a].command.y()) <
           std::make_pair(column(b), observed[b].command.y());
  });
  std::vector<double> r;
  for (int k : spots) r.push_back(residuals[k]);
  std::vector<std::pair<int, int>> pairs;
  for (size_t k = 0; k + 1 < spots.size(); ++k) {
    if (column(spots[k]) == column(spots[k + 1])) {
      pairs.push_back({static_cast<int>(k), static_cast<int>(k + 1)});
    }
  }
  const auto extent = [&](int k) {
    const Vector2d& c = observed[spots[k]].command;
    return Eigen::Vector4d(c.x(), c.x(), c.y(), c.y());
  };
  return Located(r, pairs, extent, "spots", "at");
}

// Both channels' structure: the heights along their lines and the spots along their columns.
struct CellStructure {
  Structure heights, spots;
  // A channel says nothing without enough neighbours: the test is over those that do.
  int channels() const { return (heights.tested ? 1 : 0) + (spots.tested ? 1 : 0); }
  bool Flagged() const { return heights.Flagged(channels()) || spots.Flagged(channels()); }
  // The smaller p, Bonferroni-adjusted over the channels tested.
  double p() const { return std::min(1.0, std::max(1, channels()) * std::min(heights.p, spots.p)); }
  std::string where() const {
    std::string w;
    for (const Structure* c : {&heights, &spots}) {
      if (c->Flagged(channels())) w += (w.empty() ? "" : "; ") + c->where;
    }
    return w;
  }
};

CellStructure StructureOf(const std::vector<Observation>& obs, const std::vector<double>& residuals,
                          const std::vector<Pass>& passes, double bin_mm) {
  return {LineStructure(obs, residuals, passes, bin_mm), SpotStructure(obs, residuals)};
}

// Where each line leaves each step's top at the gauge's two ends: the outermost point on the
// top followed inward by three points each within 2.5 of the line's median spacing (stray
// centres beyond the end are not the end). Lines whose ends are not within 2 mm of the gauge's
// give none.
void AddGaugeEnds(const geometry::Cloud& cloud, const inspect::StepGaugeSpec& gauge,
                  double stage_z_mm, int pass, std::vector<Observation>* obs) {
  std::map<std::pair<int, int>, std::vector<std::pair<double, Vector2d>>> tops;  // y, pixel
  for (const geometry::CloudPoint& cp : cloud) {
    const Vector3d q = cp.point_in_galvo.cast<double>() - Vector3d(0, 0, stage_z_mm);
    const int step = CellModel::StepAtX(gauge, q.x());
    if (step < 0) continue;
    if (std::abs(q.z() - gauge.base_z_mm - gauge.heights_mm[step]) > 1.0) continue;
    tops[{cp.line, step}].push_back({q.y(), Vector2d(cp.pixel_u, cp.pixel_v)});
  }
  for (auto& [key, top] : tops) {
    if (top.size() < 10) continue;
    std::sort(top.begin(), top.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<double> gaps;
    for (size_t i = 1; i < top.size(); ++i) gaps.push_back(top[i].first - top[i - 1].first);
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    const double joined = 2.5 * gaps[gaps.size() / 2];
    const int n = static_cast<int>(top.size());
    // The end: the outermost point followed inward by kJoined points each within `joined`.
    constexpr int kJoined = 3;
    const auto run_from = [&](int i, int dir) {
      for (int k = 0; k < kJoined; ++k) {
        const int a = i + dir * k, b = a + dir;
        if (b < 0 || b >= n || std::abs(top[b].first - top[a].first) > joined) return false;
      }
      return true;
    };
    int lo = 0, hi = n - 1;
    while (lo < n && !run_from(lo, +1)) ++lo;
    while (hi >= 0 && !run_from(hi, -1)) --hi;
    const double y_lo = gauge.center_y_mm - 0.5 * gauge.length_mm;
    const double y_hi = gauge.center_y_mm + 0.5 * gauge.length_mm;
    // Both ends within 2 mm of the gauge's, neither beyond it by more.
    if (!(lo < hi) || std::abs(top[lo].first - y_lo) > 2.0 || std::abs(top[hi].first - y_hi) > 2.0) {
      continue;
    }
    for (const auto& [index, side] : {std::pair{lo, -1}, std::pair{hi, +1}}) {
      Observation o;
      o.pixel = top[index].second;
      o.pass = pass;
      o.line = key.first;
      o.step = key.second;
      o.kind = kEnd;
      o.side = side;
      obs->push_back(o);
    }
  }
}

// The pointer parked at every spot of the spec on the plate (commanded at the stage's height,
// so focused on the plate's top), found against a frame with the pointer off; a spot not found is warned about
// and left out. The exposure is left at the spots'.
Status MeasureSpots(hw::Machine& machine, const DiagnoseMachineSpec& spec, const Pass& pass,
                    int pass_index, const RunOptions& options, std::vector<Observation>* obs,
                    std::vector<std::string>* warnings) {
  INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(spec.spot_exposure_ms * 1e3));
  INSITU_RETURN_IF_ERROR(machine.scanner->StopPointer());
  auto dark = machine.camera->Grab();
  if (!dark.ok()) return dark.status().Prefixed("spots: camera");
  PhaseProgress progress(options, "spots at stage " + std::to_string(pass.stage_z_mm) + " mm",
                         "spots", static_cast<double>(spec.spot_x_mm.size() * spec.spot_y_mm.size()));
  int index = 0;
  for (double x : spec.spot_x_mm) {
    for (double y : spec.spot_y_mm) {
      if (options.cancel && options.cancel->load()) {
        (void)machine.scanner->StopPointer();
        return Status(StatusCode::kCancelled, "cancelled");
      }
      const Vector3d p(x, y, pass.stage_z_mm);  // focused on the plate's top
      Status on = machine.scanner->StartPointerLine(p, p, 1.0);
      if (!on.ok()) return on.Prefixed("spots");
      machine.clock->SleepFor(0.005);
      auto lit = machine.camera->Grab();
      (void)machine.scanner->StopPointer();
      if (!lit.ok()) return lit.status().Prefixed("spots: camera");
      progress.Update(++index);
      auto spot = vision::FindSpot(vision::ViewOf(*lit), vision::ViewOf(*dark), {});
      if (!spot.ok()) {
        warnings->push_back("spot at (" + std::to_string(x) + ", " + std::to_string(y) +
                            ") mm, stage " + std::to_string(pass.stage_z_mm) +
                            " mm: " + spot.status().message());
        continue;
      }
      for (Kind kind : {kSpotX, kSpotY}) {
        Observation o;
        o.pixel = spot->center;
        o.pass = pass_index;
        o.line = index - 1;
        o.kind = kind;
        o.command = Vector2d(x, y);
        obs->push_back(o);
      }
    }
  }
  return Status::Ok();
}

}  // namespace

Status CheckDiagnoseMachineJob(const LoadedJob& job) {
  DiagnoseMachineSpec spec;
  hw::MachineConfig config;
  return ReadSpec(job, &spec, &config);
}

Result<Report> RunDiagnoseMachineJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  DiagnoseMachineSpec spec;
  hw::MachineConfig config;
  INSITU_RETURN_IF_ERROR(ReadSpec(job, &spec, &config));
  spec.scan.scan.binning = 1;
  INSITU_ASSIGN_OR_RETURN(ScanMachine up, BringUp(job, spec.scan, config, options, {hw::Role::kStage}));
  hw::Machine& machine = up.machine;
  const calib::CalibrationSet& cal = up.calibration;
  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir, machine.warnings));
  auto finish = [&](bool ok, const std::string& error,
                    StatusCode code = StatusCode::kFailedPrecondition) {
    return FinishReport(report, ok, error, wall_start, options.out_dir, code);
  };
  auto log = Logger("job");
  const inspect::StepGaugeSpec& gauge = spec.scan.gauge;
  const std::string no_baseline = "no baseline at " + spec.baseline_path +
                                  ": run this job once right after calibrating, with "
                                  "--set diagnosis.record_baseline=true (what the calibration "
                                  "itself leaves is not a change of the machine)";
  if (!spec.record_baseline && !std::filesystem::exists(spec.baseline_path)) {
    return finish(false, no_baseline);
  }

  // The scans: one pass per stage height, every stripe centre binned along its line.
  std::vector<Pass> passes;
  std::vector<Observation> obs;
  for (size_t p = 0; p < spec.stage_z_mm.size(); ++p) {
    const double z = spec.stage_z_mm[p];
    const Status moved = machine.stage->MoveTo(z);
    if (!moved.ok()) return finish(false, "stage: " + moved.ToString(), moved.code());
    PhaseProgress progress(options, "scan at stage " + std::to_string(z) + " mm", "lines",
                           spec.scan.scan.line_count());
    ScanOptions pass_scan = spec.scan.scan;
    if (spec.refocus) pass_scan.focus_z_mm += z;
    // The gauge rides on the stage: the heights its stripe can come from move with it.
    pass_scan.height_range_mm[0] += z;
    pass_scan.height_range_mm[1] += z;
    auto scanned = RunScan(
        machine, pass_scan, spec.scan.extraction, cal,
        [&](int done, int) { progress.Update(done); }, options.cancel);
    if (!scanned.ok()) return finish(false, scanned.status().ToString(), scanned.status().code());
    ReportScanLight(scanned->stats, &report);  // each pass's; the last one's metrics stay
    Pass pass;
    pass.stage_z_mm = z;
    pass.focus_z_mm = pass_scan.focus_z_mm;
    for (int i = 0; i < spec.scan.scan.line_count(); ++i) {
      const double x = spec.scan.scan.line_x(i);
      pass.lines.push_back({Vector3d(x, pass_scan.y_start_mm, pass_scan.focus_z_mm),
                            Vector3d(x, pass_scan.y_end_mm, pass_scan.focus_z_mm)});
    }
    passes.push_back(pass);
    // Bins along each line: the mean pixel of the points on one step within bin_mm of y.
    std::map<std::tuple<int, int, int>, std::pair<Vector2d, int>> bins;
    for (const geometry::CloudPoint& cp : scanned->cloud) {
      const Vector3d q = cp.point_in_galvo.cast<double>() - Vector3d(0, 0, z);
      const int step = CellModel::StepOf(gauge, q.head<2>());
      if (step < 0) continue;
      // The point must be on the step's top, not its side or the plate: within 1 mm.
      if (std::abs(q.z() - gauge.base_z_mm - gauge.heights_mm[step]) > 1.0) continue;
      const int bin = static_cast<int>(std::floor(q.y() / spec.bin_mm));
      auto it = bins.try_emplace({cp.line, step, bin}, Vector2d::Zero(), 0).first;
      auto& b = it->second;
      b.first += Vector2d(cp.pixel_u, cp.pixel_v);
      b.second += 1;
    }
    for (const auto& [key, b] : bins) {
      if (b.second < 3) continue;
      obs.push_back({b.first / b.second, static_cast<int>(p), std::get<0>(key), std::get<1>(key),
                     std::get<2>(key), 0.0});
    }
    const size_t heights = obs.size();
    if (spec.gauge_fixed) AddGaugeEnds(scanned->cloud, gauge, z, static_cast<int>(p), &obs);
    const size_t ends = obs.size() - heights;
    if (!spec.spot_x_mm.empty() && !spec.spot_y_mm.empty()) {
      const Status spotted = MeasureSpots(machine, spec, passes.back(), static_cast<int>(p),
                                          options, &obs, &report.warnings);
      if (!spotted.ok()) return finish(false, spotted.ToString(), spotted.code());
    }
    log->info("diagnose_machine: stage {} mm, {} points in {} bins, {} line ends, {} spots", z,
              scanned->cloud.size(), bins.size(), ends, (obs.size() - heights - ends) / 2);
  }
  (void)machine.stage->MoveTo(0.0);
  const auto heights = static_cast<size_t>(
      std::count_if(obs.begin(), obs.end(), [](const Observation& o) { return o.kind == kHeight; }));
  if (heights < 50) {
    return finish(false,
                  "only " + std::to_string(heights) +
                      " binned points on the gauge's tops: is the gauge where artifact.center_mm "
                      "says, and in the scan's x range?");
  }
  const bool two_heights = spec.stage_z_mm.size() >= 2;
  const bool two_focus = two_heights && spec.refocus;
  // A line's end: its step and bin -100000 (y low) or +100000 (y high); a spot: its command's
  // x for the line, step -1 (x) or -2 (y), and its y in um for the bin.
  const auto key_of = [&](const Observation& o) {
    const double z = passes[o.pass].stage_z_mm;
    switch (o.kind) {
      case kHeight: return KeyOf(z, spec.scan.scan.line_x(o.line), o.step, o.bin);
      case kEnd: return KeyOf(z, spec.scan.scan.line_x(o.line), o.step, 100000 * o.side);
      case kSpotX:
      case kSpotY:
        return KeyOf(z, o.command.x(), o.kind == kSpotX ? -1 : -2,
                     static_cast<int>(std::lround(o.command.y() * 1e3)));
    }
    return std::string();
  };
  if (spec.record_baseline) {
    // The machine as calibrated: its residuals, kept for every later diagnosis.
    CellModel as_is(cal, gauge, passes, obs, Candidates(two_heights, two_focus));
    std::vector<int> all(obs.size());
    for (size_t k = 0; k < obs.size(); ++k) all[k] = static_cast<int>(k);
    std::vector<double> r;
    if (!as_is.Residuals(std::vector<double>(as_is.parameters(), 0.0), all, &r)) {
      return finish(false, "baseline: the scan's rays miss their light planes");
    }
    std::string text =
        "# insitu diagnose_machine baseline: residuals of the machine as calibrated\n"
        "# heights (step >= 0, bin along y), the gauge's ends (bin -100000: y low, 100000: y "
        "high) and pointer spots (step -1: x, -2: y; line_x: the spot's x, bin: its y in um)\n"
        "# calibration: " +
        spec.scan.machine.calibration_path + "\n" + RefocusLine(spec.refocus) + "\n" +
        FramesLine(spec.scan.scan) +
        "\nstage_z_mm,line_x_mm,step,bin,residual_mm\n";
    double ss = 0;
    for (size_t k = 0; k < obs.size(); ++k) {
      char line[160];
      std::snprintf(line, sizeof line, "%s,%.6f\n", key_of(obs[k]).c_str(), r[k]);
      text += line;
      ss += r[k] * r[k];
    }
    const std::string baseline_path =
        OutputPath(spec.baseline_path, "diagnosis.baseline", options, &report.warnings);
    const Status saved = WriteFileAtomically(baseline_path, text);
    if (!saved.ok()) return finish(false, "baseline: " + saved.ToString(), saved.code());
    const double rms = std::sqrt(ss / obs.size());
    report.metrics["observations"] = static_cast<double>(obs.size());
    report.metrics["baseline_rms_mm"] = rms;
    report.artifacts["baseline"] = baseline_path;
    // The diagnose keys, for the machine as calibrated: nothing to explain by definition.
    const nlohmann::ordered_json as_is_json = {{"rms_mm", rms}, {"cv_rms_mm", rms}};
    report.extra_json["n_points"] = std::to_string(obs.size());
    report.extra_json["nominal"] = as_is_json.dump();
    report.extra_json["effects"] = "[]";
    report.extra_json["cause"] = "[]";
    report.extra_json["extended"] = as_is_json.dump();
    report.extra_json["gain"] = "1";
    report.extra_json["unexplained"] = "false";
    log->info("diagnose_machine: baseline of {} bins recorded in {} ({:.1f} um rms)", obs.size(),
              baseline_path, 1e3 * rms);
    return finish(true, "");
  }
  {
    std::ifstream in(spec.baseline_path);
    if (!in) {
      return finish(false, no_baseline);
    }
    std::map<std::string, double> base;
    std::string refocus_line, frames_line;
    std::string line;
    int row = 0;
    while (std::getline(in, line)) {
      ++row;
      if (line.rfind("# refocus:", 0) == 0) refocus_line = line;
      if (line.rfind("# frames:", 0) == 0) frames_line = line;
      if (line.empty() || line[0] == '#' || line.rfind("stage_z_mm", 0) == 0) continue;
      const size_t comma = line.rfind(',');
      char* end = nullptr;
      const double v =
          comma == std::string::npos ? NAN : std::strtod(line.c_str() + comma + 1, &end);
      const bool whole =
          end != nullptr && std::string(end).find_first_not_of(" \t\r") == std::string::npos;
      if (!std::isfinite(v) || !whole || std::count(line.begin(), line.end(), ',') != 4) {
        return finish(false, spec.baseline_path + ":" + std::to_string(row) +
                                 ": expected stage_z_mm,line_x_mm,step,bin,residual_mm");
      }
      base[line.substr(0, comma)] = v;
    }
    // The passes must have been focused as this run focuses them: a baseline from passes drawn
    // at another focus holds the calibration's residuals there, not here.
    if (refocus_line != RefocusLine(spec.refocus)) {
      return finish(false,
                    spec.baseline_path + ": recorded with " +
                        (refocus_line.empty() ? "no refocus line (an older baseline)"
                                              : "'" + refocus_line + "'") +
                        ", this run has '" + RefocusLine(spec.refocus) +
                        "': record the baseline again (--set diagnosis.record_baseline=true)");
    }
    if (frames_line != FramesLine(spec.scan.scan)) {
      return finish(false,
                    spec.baseline_path + ": recorded with " +
                        (frames_line.empty() ? "frames made otherwise (an older baseline)"
                                             : "'" + frames_line + "'") +
                        ", this run has '" + FramesLine(spec.scan.scan) +
                        "': record the baseline again (--set diagnosis.record_baseline=true)");
    }
    std::vector<Observation> kept;
    std::map<Kind, std::pair<int, int>> with_baseline;  // kind: (measured, with a baseline)
    for (Observation o : obs) {
      auto it = base.find(key_of(o));
      ++with_baseline[o.kind].first;
      if (it == base.end()) continue;
      ++with_baseline[o.kind].second;
      o.baseline_mm = it->second;
      kept.push_back(o);
    }
    for (const auto& [kind, counts] : with_baseline) {
      if (kind == kHeight || counts.second > 0) continue;
      report.warnings.push_back(
          std::string(kind == kEnd ? "the gauge's ends" : "the pointer spots") +
          " have no baseline in " + spec.baseline_path +
          " (recorded without them): the camera's and the mirrors' shifts along the lines cannot "
          "be told; record the baseline again (--set diagnosis.record_baseline=true)");
    }
    report.metrics["observations_without_baseline"] = static_cast<double>(obs.size() - kept.size());
    if (kept.size() < obs.size() / 2) {
      return finish(false, "only " + std::to_string(kept.size()) + " of " +
                               std::to_string(obs.size()) + " binned points have a baseline in " +
                               spec.baseline_path + ": was it recorded with this job's scan?");
    }
    obs = std::move(kept);
  }
  const std::vector<fit::ParameterGroup> all_candidates = Candidates(two_heights, two_focus);
  CellModel model(cal, gauge, passes, obs, all_candidates);
  // No nuisance: the heights of a level gauge standing on the plate do not depend on where on
  // the plate it stands (its placement only decides which step a point is on, fixed above).
  fit::GroupSelectionOptions sel = spec.selection;
  auto d = fit::DiagnoseGroups(model, {}, all_candidates, sel);
  if (!d.ok()) return finish(false, "diagnosis: " + d.status().ToString(), d.status().code());

  // Structure left after the causes (LineStructure): an off-library change leaves it. Causes
  // that took most of the change's structure away (three quarters of its variance) stay named
  // beside the flag, as in fit::Diagnose: a bumped camera is still named when worn bearings
  // leave their own structure beside it. Causes that only fitted part of a change they do not
  // explain are reported as partial, never as its cause.
  const CellStructure before = StructureOf(obs, d->residual_nominal, passes, spec.bin_mm);
  const CellStructure left = StructureOf(obs, d->residual_extended, passes, spec.bin_mm);
  const bool unexplained = left.Flagged();
  // Most of each flagged channel's structure taken away.
  bool explains_most = true;
  for (const auto& [l, b] :
       {std::pair{&left.heights, &before.heights}, std::pair{&left.spots, &before.spots}}) {
    if (l->Flagged(left.channels()) &&
        l->structure_mm * l->structure_mm > 0.25 * b->structure_mm * b->structure_mm) {
      explains_most = false;
    }
  }
  std::vector<fit::GroupReport> partial_groups;
  if (unexplained && !d->cause.empty() && !explains_most) {
    d->notes.push_back("structure is left (" + left.where() + ") beside the best of the library (" +
                       Join(d->cause) +
                       "), which took less than three quarters of it: they fit part of a change "
                       "they do not explain, so none is named");
    partial_groups = std::move(d->groups);
    d->groups.clear();
    d->cause.clear();
  }
  if (d->residual_extended.size() != obs.size()) {
    d->notes.push_back("the residuals could not be evaluated: no structure test");
  }
  const bool partial = !partial_groups.empty();
  const double extended_rms = partial ? d->nominal_rms : d->extended_rms;
  const double extended_cv_rms = partial ? d->nominal_cv_rms : d->extended_cv_rms;
  const double gain = partial ? 1.0 : d->gain;

  auto& m = report.metrics;
  m["observations"] = static_cast<double>(obs.size());
  m["observations_gauge_ends"] = static_cast<double>(
      std::count_if(obs.begin(), obs.end(), [](const Observation& o) { return o.kind == kEnd; }));
  m["observations_spots"] = static_cast<double>(
      std::count_if(obs.begin(), obs.end(), [](const Observation& o) { return o.kind == kSpotX; }));
  m["passes"] = static_cast<double>(passes.size());
  m["nominal_rms_mm"] = d->nominal_rms;
  m["nominal_cv_rms_mm"] = d->nominal_cv_rms;
  m["extended_rms_mm"] = extended_rms;
  m["extended_cv_rms_mm"] = extended_cv_rms;
  m["gain"] = gain;
  m["residual_lag1_correlation"] = left.heights.rho;
  m["residual_noise_mm"] = left.heights.noise_mm;
  m["residual_structure_mm"] = left.heights.structure_mm;
  m["nominal_structure_mm"] = before.heights.structure_mm;
  m["residual_spot_noise_mm"] = left.spots.noise_mm;
  m["residual_spot_structure_mm"] = left.spots.structure_mm;
  m["nominal_spot_structure_mm"] = before.spots.structure_mm;
  m["unexplained_p"] = left.p();
  for (const fit::GroupReport& g : d->groups) {
    for (size_t k = 0; k < g.params.size(); ++k) m[g.name + "_" + g.params[k]] = g.values[k];
  }
  if (!two_focus) {
    report.warnings.push_back(
        "focus_scale (the dynamic focus travel) shows only between passes focused at different "
        "heights (two diagnosis.stage_z_mm and diagnosis.refocus): not among the candidates");
  }
  if (!two_heights) {
    report.warnings.push_back(
        "one stage height: stage_scale cannot be seen (list two in "
        "diagnosis.stage_z_mm)");
  }
  if (unexplained) report.warnings.push_back("unexplained structure: " + left.where());
  nlohmann::ordered_json effects = nlohmann::ordered_json::array();
  for (const fit::GroupReport& g : d->groups) effects.push_back(GroupJson(g));
  nlohmann::ordered_json nominal = {{"rms_mm", d->nominal_rms}, {"cv_rms_mm", d->nominal_cv_rms}};
  nlohmann::ordered_json extended = {{"rms_mm", extended_rms}, {"cv_rms_mm", extended_cv_rms}};
  if (partial) {
    nlohmann::ordered_json p = nlohmann::ordered_json::array();
    for (const fit::GroupReport& g : partial_groups) p.push_back(GroupJson(g));
    report.extra_json["partial"] = p.dump();
  }
  if (unexplained)
    report.extra_json["unexplained_where"] = nlohmann::ordered_json(left.where()).dump();
  report.extra_json["unexplained_p"] = nlohmann::ordered_json(left.p()).dump();
  report.extra_json["n_points"] = std::to_string(obs.size());
  report.extra_json["nominal"] = nominal.dump();
  report.extra_json["effects"] = effects.dump();
  report.extra_json["cause"] = nlohmann::ordered_json(d->cause).dump();
  report.extra_json["extended"] = extended.dump();
  report.extra_json["gain"] = nlohmann::ordered_json(gain).dump();
  report.extra_json["unexplained"] = unexplained ? "true" : "false";
  report.extra_json["notes"] = nlohmann::ordered_json(d->notes).dump();

  // The plot: residual heights over the gauge, as calibrated and with the causes.
  std::vector<int> all;  // the heights' bins
  std::vector<double> as_calibrated, after_causes;
  for (size_t k = 0; k < obs.size(); ++k) {
    if (obs[k].kind != kHeight) continue;
    all.push_back(static_cast<int>(k));
    if (k < d->residual_nominal.size()) as_calibrated.push_back(d->residual_nominal[k]);
    if (k < d->residual_extended.size()) after_causes.push_back(d->residual_extended[k]);
  }
  std::vector<Vector3d> points;
  if (model.Points(std::vector<double>(model.parameters(), 0.0), all, &points)) {
    std::string after = partial ? "best partial fit, no cause" : "with the causes";
    const std::vector<fit::GroupReport>& shown = partial ? partial_groups : d->groups;
    if (!shown.empty()) {
      after += " (";
      for (size_t k = 0; k < shown.size(); ++k) after += (k ? " + " : "") + shown[k].name;
      after += ")";
    }
    const std::string png = (std::filesystem::path(options.out_dir) / "residuals.png").string();
    if (SaveResidualMap(points, as_calibrated, after_causes, after, png).ok()) {
      report.artifacts["residuals"] = "residuals.png";
    }
  }
  std::string summary = d->cause.empty() ? "the machine is as calibrated" : "cause:";
  if (unexplained) summary = "a change no effect of the library explains (" + left.where() + ")";
  for (const std::string& c : d->cause) summary += " " + c;
  log->info("diagnose_machine: {} ({:.1f} um held out as calibrated, {:.1f} um with the causes)",
            summary, d->nominal_cv_rms * 1e3, extended_cv_rms * 1e3);
  return finish(true, "");
}

}  // namespace insitu::job
