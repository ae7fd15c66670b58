// The calibrate job: camera intrinsics from chessboard views, then the camera's pose in the
// galvo frame from pointer spots, written as a new calibration set only if both succeed.
#include "job/calibrate.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "insitu/calib/calibration.h"
#include "insitu/calib/camera_calibration.h"
#include "insitu/core/log.h"
#include "insitu/job/scan.h"
#include "insitu/vision/background.h"
#include "insitu/vision/canvas.h"
#include "insitu/vision/stripe.h"
#include "insitu/vision/targets.h"
#include "job/cell.h"
#include "job/output_path.h"
#include "job/phase.h"
#include "job/progress.h"
#include "job/room_exposure.h"
#include "job/save_calibration.h"

namespace insitu::job {
namespace {

bool Cancelled(const RunOptions& options) {
  return options.cancel != nullptr && options.cancel->load();
}

struct CalibrateSpec {
  MachineSpec machine;
  calib::BoardGeometry board;
  int views = 15;
  double board_exposure_ms = 300.0;
  bool board_auto_exposure = true;  // the first view sets it (job/room_exposure.h)
  double board_stage_z_mm = -20.0;
  calib::IntrinsicsOptions intrinsics;
  double spot_exposure_ms = 0.5;
  std::vector<double> spot_stage_z_mm{0.0, 10.0};
  double spot_half_size_mm = 40.0;
  double spot_step_mm = 20.0;
  calib::AlignmentOptions alignment;
  // Height calibration (seed 000 sec. 2.2): plate at every height, line at every offset.
  bool height = true;
  double z_start_mm = -15.0, z_end_mm = 15.0, z_step_mm = 2.5;
  double x_start_mm = -30.0, x_end_mm = 30.0, x_step_mm = 5.0;
  double y_start_mm = -50.0, y_end_mm = 50.0;
  double height_exposure_ms = 150.0;
  int height_background_frames = 2;  // pointer-off frames per height, taken off each frame
  double speed_mm_per_s = 5000.0;
  std::string output_path;
};

std::vector<double> Steps(double from, double to, double step) {
  std::vector<double> v;
  for (int i = 0; from + i * step <= to + 1e-9; ++i) v.push_back(from + i * step);
  return v;
}

Status ReadSpec(const LoadedJob& job, CalibrateSpec* s, hw::MachineConfig* machine) {
  ConfigReader r(job.root);
  ReadJobHeader(r, job, &s->machine);
  ConfigReader& b = r.Section("board");
  b.Read("inner_cols", &s->board.inner_cols);
  b.Read("inner_rows", &s->board.inner_rows);
  b.Read("square_mm", &s->board.square_mm);
  if (b.ok() && (s->board.inner_cols < 3 || s->board.inner_rows < 3)) {
    b.Fail("inner_cols", "must be >= 3 (and inner_rows)");
  }
  if (b.ok() && !(s->board.square_mm > 0)) b.Fail("square_mm", "must be > 0");
  ConfigReader& in = r.Section("intrinsics");
  in.Read("views", &s->views);
  in.Read("exposure_ms", &s->board_exposure_ms);
  in.Read("auto_exposure", &s->board_auto_exposure);
  in.Read("stage_z_mm", &s->board_stage_z_mm);
  in.Read("min_views", &s->intrinsics.min_views);
  in.Read("min_coverage", &s->intrinsics.min_coverage);
  in.Read("max_rms_px", &s->intrinsics.max_rms_px);
  if (in.ok() && s->views < 1) in.Fail("views", "must be >= 1");
  if (in.ok() && !(s->board_exposure_ms > 0)) in.Fail("exposure_ms", "must be > 0");
  if (in.ok()) in.FailFromValidate(s->intrinsics.Validate());
  ConfigReader& al = r.Section("alignment");
  al.Read("exposure_ms", &s->spot_exposure_ms);
  al.Read("stage_z_mm", &s->spot_stage_z_mm);
  al.Read("half_size_mm", &s->spot_half_size_mm);
  al.Read("step_mm", &s->spot_step_mm);
  al.Read("min_spots", &s->alignment.min_spots);
  al.Read("max_rms_mm", &s->alignment.max_rms_mm);
  if (al.ok() && !(s->spot_exposure_ms > 0)) al.Fail("exposure_ms", "must be > 0");
  if (al.ok() && !(s->spot_step_mm > 0)) al.Fail("step_mm", "must be > 0");
  if (al.ok() && !(s->spot_half_size_mm > 0)) al.Fail("half_size_mm", "must be > 0");
  if (al.ok() && s->spot_stage_z_mm.empty()) al.Fail("stage_z_mm", "must list at least one height");
  if (al.ok()) al.FailFromValidate(s->alignment.Validate());
  if (r.Has("height")) {
    ConfigReader& h = r.Section("height");
    h.Read("enabled", &s->height);
    h.Read("z_start_mm", &s->z_start_mm);
    h.Read("z_end_mm", &s->z_end_mm);
    h.Read("z_step_mm", &s->z_step_mm);
    h.Read("x_start_mm", &s->x_start_mm);
    h.Read("x_end_mm", &s->x_end_mm);
    h.Read("x_step_mm", &s->x_step_mm);
    h.Read("y_start_mm", &s->y_start_mm);
    h.Read("y_end_mm", &s->y_end_mm);
    h.Read("exposure_ms", &s->height_exposure_ms);
    h.Read("background_frames", &s->height_background_frames);
    h.Read("speed_mm_per_s", &s->speed_mm_per_s);
    if (h.ok() && !(s->z_step_mm > 0)) h.Fail("z_step_mm", "must be > 0");
    if (h.ok() && !(s->x_step_mm > 0)) h.Fail("x_step_mm", "must be > 0");
    if (h.ok() && !(s->z_end_mm > s->z_start_mm)) h.Fail("z_end_mm", "must exceed z_start_mm");
    if (h.ok() && !(s->x_end_mm > s->x_start_mm)) h.Fail("x_end_mm", "must exceed x_start_mm");
    if (h.ok() && !(s->height_exposure_ms > 0)) h.Fail("exposure_ms", "must be > 0");
    if (h.ok() && (s->height_background_frames < 0 || s->height_background_frames > 64)) {
      h.Fail("background_frames", "must be in [0, 64]");
    }
    if (h.ok() && !(s->speed_mm_per_s > 0)) h.Fail("speed_mm_per_s", "must be > 0");
  }
  ConfigReader& out = r.Section("output");
  out.Require("calibration");
  std::string path;
  out.Read("calibration", &path);
  s->output_path = ResolvePath(job.folder, path);
  INSITU_RETURN_IF_ERROR(r.Finish());
  return MachineConfigFor(job, s->machine, machine);
}

// The frame with marks drawn on it, half size: what the operator looks at to judge a view.
Status SaveOverlay(const Frame& frame, const std::vector<Eigen::Vector2d>& points, int rgb,
                   const std::string& path) {
  auto picture = vision::Canvas::FromGray(vision::ViewOf(frame));
  if (!picture.ok()) return DeviceError("cannot write " + path + ": " + picture.status().message());
  for (const Eigen::Vector2d& p : points) {
    // Whole pixels, truncated.
    const Eigen::Vector2d at(static_cast<int>(p.x()), static_cast<int>(p.y()));
    picture->Circle(at, 9, {.rgb = rgb, .thickness = 3, .smooth = true});
  }
  picture->Resize(0.5);
  return picture->WritePng(path);
}

// What every phase of a calibrate job works with.
struct CalibrateRun {
  const CalibrateSpec& spec;
  const RunOptions& options;
  hw::Machine& machine;
  Report& report;
  std::filesystem::path dir;  // the job's output folder
};

// Every stage height the job will ask for is checked against the stage's travel before the
// first frame, so a bad job file fails now and not after minutes of measuring.
Status CheckStageTravel(const CalibrateSpec& spec, const hw::Stage& stage,
                        const std::string& job_path) {
  const double lo = stage.min_z_mm(), hi = stage.max_z_mm();
  std::vector<std::pair<std::string, double>> heights{
      {"intrinsics.stage_z_mm", spec.board_stage_z_mm}};
  for (double z : spec.spot_stage_z_mm) heights.emplace_back("alignment.stage_z_mm", z);
  if (spec.height) {
    heights.emplace_back("height.z_start_mm", spec.z_start_mm);
    heights.emplace_back("height.z_end_mm", spec.z_end_mm);
  }
  for (const auto& [key, z] : heights) {
    if (z < lo || z > hi) {
      char text[160];
      std::snprintf(text, sizeof text, ": %g mm is outside the stage travel [%g, %g] mm", z, lo,
                    hi);
      return InvalidArgument(job_path + ": " + key + text);
    }
  }
  return Status::Ok();
}

// 1. Intrinsics: the operator holds the board in `views` poses. The camera's identity comes
// from the camera, its lens from the previous calibration.
Result<calib::CameraIntrinsics> MeasureIntrinsics(CalibrateRun& run,
                                                  const calib::CalibrationSet& previous) {
  const CalibrateSpec& spec = run.spec;
  hw::Machine& machine = run.machine;
  Report& report = run.report;
  const hw::CameraInfo info = machine.camera->info();
  for (const Status& s : {machine.camera->SetBinning(1),
                          machine.camera->SetExposure(spec.board_exposure_ms * 1e3),
                          machine.stage->MoveTo(spec.board_stage_z_mm)}) {
    if (!s.ok()) return PhaseFailure(s, "intrinsics: ");
  }
  (void)machine.scanner->StopPointer();
  std::vector<std::vector<Eigen::Vector2d>> corners;
  PhaseProgress progress(run.options, "intrinsics", "board views", spec.views);
  const vision::ChessboardOptions board{spec.board.inner_cols, spec.board.inner_rows};
  double exposure_ms = spec.board_exposure_ms, lo_ms = 1e300, hi_ms = 0.0;
  int shots = 0;
  for (int k = 0; k < spec.views; ++k) {
    if (Cancelled(run.options)) return Status(StatusCode::kCancelled, "cancelled");
    const Status placed = machine.person->PlaceBoard(k, spec.views);
    if (!placed.ok()) return PhaseFailure(placed);
    if (spec.board_auto_exposure) {
      // Each pose turns the board to the room's light otherwise: each view is exposed for
      // itself, from the last one's exposure.
      auto exposed =
          ExposeForBoard(*machine.camera, exposure_ms, spec.board_exposure_ms / 10.0,
                         spec.board_exposure_ms * 10.0, board, run.options.cancel);
      if (!exposed.ok()) return PhaseFailure(exposed.status(), "intrinsics: ");
      shots += exposed->shots;
      if (exposed->white_fraction > 0) {
        exposure_ms = exposed->exposure_ms;
        lo_ms = std::min(lo_ms, exposure_ms);
        hi_ms = std::max(hi_ms, exposure_ms);
      }
    }
    auto frame = machine.camera->Grab();
    if (!frame.ok()) return PhaseFailure(frame.status());
    auto found = vision::FindChessboard(vision::ViewOf(*frame), board);
    if (found.ok()) {
      if (corners.empty()) {
        const Status s =
            SaveOverlay(*frame, *found, 0xd62728, (run.dir / "board_view.png").string());
        if (s.ok()) report.artifacts["board_view"] = "board_view.png";
      }
      corners.push_back(*found);
    } else {
      report.warnings.push_back("view " + std::to_string(k) + ": " + found.status().message());
    }
    progress.Update(k + 1);
  }
  const Status removed = machine.person->RemoveBoard();
  if (!removed.ok()) return PhaseFailure(removed);
  if (hi_ms > 0) {
    report.metrics["intrinsics_exposure_ms_min"] = lo_ms;
    report.metrics["intrinsics_exposure_ms_max"] = hi_ms;
    report.metrics["intrinsics_exposure_shots"] = shots;
  }
  calib::IntrinsicsSummary intr = calib::CalibrateIntrinsics(
      corners, spec.board, info.sensor_width_px, info.sensor_height_px, spec.intrinsics);
  report.metrics["intrinsics_views"] = intr.views;
  report.metrics["intrinsics_coverage"] = intr.coverage;
  if (!intr.ok) return FailedPrecondition("camera intrinsics: " + intr.message);
  report.metrics["intrinsics_rms_px"] = intr.rms_px;
  report.metrics["fx_px"] = intr.intrinsics.fx;
  report.metrics["fy_px"] = intr.intrinsics.fy;
  report.metrics["cx_px"] = intr.intrinsics.cx;
  report.metrics["cy_px"] = intr.intrinsics.cy;
  report.metrics["k1"] = intr.intrinsics.k1;
  report.metrics["k2"] = intr.intrinsics.k2;
  intr.intrinsics.model = info.model;
  intr.intrinsics.serial = info.serial;
  intr.intrinsics.lens = previous.camera.lens;
  Logger("job")->info("intrinsics: {} views, RMS {:.3f} px, fx {:.1f} px", intr.views, intr.rms_px,
                      intr.intrinsics.fx);
  return intr.intrinsics;
}

// 2. Camera pose in the galvo frame: pointer spots on the bare stage plate at known
// positions (a part would put them at unknown heights).
Result<Eigen::Isometry3d> AlignCameraToGalvo(CalibrateRun& run,
                                             const calib::CameraIntrinsics& intrinsics,
                                             const calib::CalibrationSet& previous) {
  const CalibrateSpec& spec = run.spec;
  hw::Machine& machine = run.machine;
  Report& report = run.report;
  const Status cleared = machine.person->ClearTable();
  if (!cleared.ok()) return PhaseFailure(cleared);
  const Status exposed = machine.camera->SetExposure(spec.spot_exposure_ms * 1e3);
  if (!exposed.ok()) return PhaseFailure(exposed, "alignment: ");
  std::vector<calib::GalvoSpot> spots;
  const int per_level = static_cast<int>(
      std::pow(std::floor(2.0 * spec.spot_half_size_mm / spec.spot_step_mm + 1e-9) + 1, 2));
  PhaseProgress spotting(run.options, "alignment", "spots",
                         static_cast<double>(per_level * spec.spot_stage_z_mm.size()));
  int spot_frames = 0;
  std::vector<Eigen::Vector2d> first_level;
  Frame last;
  for (double z : spec.spot_stage_z_mm) {
    const Status moved = machine.stage->MoveTo(z);
    if (!moved.ok()) return PhaseFailure(moved, "alignment: ");
    (void)machine.scanner->StopPointer();
    auto dark = machine.camera->Grab();
    if (!dark.ok()) return PhaseFailure(dark.status());
    for (double x = -spec.spot_half_size_mm; x <= spec.spot_half_size_mm + 1e-9;
         x += spec.spot_step_mm) {
      for (double y = -spec.spot_half_size_mm; y <= spec.spot_half_size_mm + 1e-9;
           y += spec.spot_step_mm) {
        if (Cancelled(run.options)) return Status(StatusCode::kCancelled, "cancelled");
        spotting.Update(spot_frames++);
        const Eigen::Vector3d p(x, y, z);
        const Status on = machine.scanner->StartPointerLine(p, p, 1.0);
        if (!on.ok()) return PhaseFailure(on, "alignment: ");
        machine.clock->SleepFor(0.005);
        auto lit = machine.camera->Grab();
        if (!lit.ok()) return PhaseFailure(lit.status());
        auto spot = vision::FindSpot(vision::ViewOf(*lit), vision::ViewOf(*dark), {});
        if (!spot.ok()) {
          report.warnings.push_back("spot at (" + std::to_string(x) + ", " + std::to_string(y) +
                                    ", " + std::to_string(z) + "): " + spot.status().message());
          continue;
        }
        // On a head a field calibration has measured, the spot is where the measured head
        // puts the pointer, not where it was asked to go: the pose then stays metric (the
        // design map would fold the head's scale into the camera's pose).
        Eigen::Vector3d where = p;
        optics::ChiefRay ray;
        if (previous.head.measured && previous.head.PointerRay(p, &ray)) where = ray.AtHeight(z);
        spots.push_back({where, spot->center});
        if (z == spec.spot_stage_z_mm.front()) first_level.push_back(spot->center);
        last = std::move(*lit);
      }
    }
    (void)machine.scanner->StopPointer();
  }
  spotting.Update(static_cast<double>(per_level * spec.spot_stage_z_mm.size()));
  (void)machine.stage->MoveTo(0.0);
  if (!last.bytes.empty() &&
      SaveOverlay(last, first_level, 0x2ca02c, (run.dir / "spots.png").string()).ok()) {
    report.artifacts["spots"] = "spots.png";
  }
  const calib::AlignmentSummary align =
      calib::AlignCameraToGalvo(spots, intrinsics, spec.alignment);
  report.metrics["alignment_spots"] = align.spots;
  if (!align.ok) return FailedPrecondition("galvo alignment: " + align.message);
  report.metrics["alignment_rms_px"] = align.rms_px;
  report.metrics["alignment_rms_mm"] = align.rms_mm;
  report.metrics["alignment_max_mm"] = align.max_mm;
  Logger("job")->info("galvo alignment: {} spots, residual {:.4f} mm rms", align.spots,
                      align.rms_mm);
  return align.camera_from_galvo;
}

// 3. Height lookup: the bare plate at each stage height, a line at each offset (the camera's
// exposure set by the caller).
Result<calib::HeightLookup> CalibrateHeights(CalibrateRun& run) {
  const CalibrateSpec& spec = run.spec;
  hw::Machine& machine = run.machine;
  Report& report = run.report;
  const std::vector<double> zs = Steps(spec.z_start_mm, spec.z_end_mm, spec.z_step_mm);
  const std::vector<double> xs = Steps(spec.x_start_mm, spec.x_end_mm, spec.x_step_mm);
  std::vector<calib::HeightObservation> observations;
  vision::StripeOptions stripe_options;
  stripe_options.direction = vision::StripeDirection::kColumns;
  // Gray levels on the 8-bit scale, as the scan's: the same light on a 12-bit camera.
  vision::StripeExtractor extractor(stripe_options.ForBitDepth(machine.camera->info().bit_depth));
  vision::StripeResult stripe;
  PhaseProgress hp(run.options, "height calibration", "frames",
                   static_cast<double>(zs.size() * xs.size()));
  int done = 0;
  vision::Image background, subtracted;  // the room's light on the plate at this height
  vision::Image plane;                   // a colour frame in the pointer's channel
  for (double z : zs) {
    const Status moved = machine.stage->MoveTo(z);
    if (!moved.ok()) return PhaseFailure(moved, "height calibration: ");
    if (spec.height_background_frames > 0) {
      auto mean = GrabBackground(machine, spec.height_background_frames, run.options.cancel);
      if (!mean.ok()) return PhaseFailure(mean.status(), "height calibration: ");
      background = std::move(*mean);
    }
    for (double x : xs) {
      if (Cancelled(run.options)) return Status(StatusCode::kCancelled, "cancelled");
      const Status on = machine.scanner->StartPointerLine(
          {x, spec.y_start_mm, 0.0}, {x, spec.y_end_mm, 0.0}, spec.speed_mm_per_s);
      if (!on.ok()) return PhaseFailure(on, "height calibration: ");
      machine.clock->SleepFor(0.005);
      auto frame = machine.camera->Grab();
      if (!frame.ok()) return PhaseFailure(frame.status());
      vision::ImageView view = vision::ViewOf(*frame);
      if (!background.bytes.empty()) {
        const Status sub = vision::SubtractBackground(view, background.view(), &subtracted);
        if (!sub.ok()) return PhaseFailure(sub, "height calibration: ");
        view = subtracted.view();
      }
      auto stripe_plane = vision::StripePlane(view, stripe_options.colour_channel, &plane);
      if (!stripe_plane.ok()) return PhaseFailure(stripe_plane.status(), "height calibration: ");
      const Status ex = extractor.Extract(*stripe_plane, &stripe);
      if (!ex.ok()) return PhaseFailure(ex);
      calib::HeightObservation o{x, z, {}};
      const double b = frame->binning;
      for (size_t k = 0; k < stripe.status.size(); ++k) {
        if (stripe.status[k] != vision::StripeStatus::kValid) continue;
        // Full-sensor pixels: u_full = (u_b + 0.5) b - 0.5.
        o.centres.emplace_back((stripe.u(static_cast<int>(k)) + 0.5) * b - 0.5,
                               (stripe.v(static_cast<int>(k)) + 0.5) * b - 0.5);
      }
      observations.push_back(std::move(o));
      hp.Update(++done);
    }
  }
  (void)machine.scanner->StopPointer();
  (void)machine.stage->MoveTo(0.0);
  calib::HeightLookupSummary hs;
  calib::HeightLookup lookup = calib::HeightLookup::Build(observations, &hs);
  report.metrics["height_frames"] = static_cast<double>(observations.size());
  if (!hs.ok) return FailedPrecondition("height calibration: " + hs.message);
  report.metrics["height_curve_fit_rms_px"] = hs.fit_rms_px;
  report.metrics["height_curve_fit_max_px"] = hs.fit_max_px;
  report.metrics["height_curve_outliers"] = hs.outliers;
  Logger("job")->info("height lookup: {} offsets x {} heights, curve fit {:.3f} px rms", xs.size(),
                      zs.size(), hs.fit_rms_px);
  return lookup;
}

// Writes the measured set beside the report and where the job file says.
Status Save(CalibrateRun& run, const calib::CalibrationSet& set) {
  const Status saved = SaveMeasuredCalibration(
      set,
      OutputPath(run.spec.output_path, "output.calibration", run.options, &run.report.warnings),
      run.options.out_dir, &run.report);
  if (!saved.ok()) return PhaseFailure(saved);
  return Status::Ok();
}

}  // namespace

Status CheckCalibrateJob(const LoadedJob& job) {
  CalibrateSpec spec;
  hw::MachineConfig config;
  return ReadSpec(job, &spec, &config);
}

Result<Report> RunCalibrateJob(const LoadedJob& job, const RunOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  CalibrateSpec spec;
  hw::MachineConfig config;
  INSITU_RETURN_IF_ERROR(ReadSpec(job, &spec, &config));
  auto previous = calib::LoadCalibration(spec.machine.calibration_path);
  if (!previous.ok()) return previous.status().Prefixed(job.path + ": machine.calibration");
  INSITU_ASSIGN_OR_RETURN(
      hw::Machine machine,
      OpenCell(config, options,
               {hw::Role::kScanner, hw::Role::kCamera, hw::Role::kStage, hw::Role::kOperator},
               job));
  INSITU_ASSIGN_OR_RETURN(Report report, StartReport(job.kind, options.out_dir, machine.warnings));
  // A failed measurement is failed_precondition; a device's fault, the operator's abort or a
  // cancel keep their own code (exit 1 or 130, not 2: the input was fine).
  auto finish = [&](const Status& failure) {
    return FinishReport(report, failure.ok(), failure.message(), wall_start, options.out_dir,
                        failure.code());
  };
  INSITU_RETURN_IF_ERROR(CheckStageTravel(spec, *machine.stage, job.path));
  CalibrateRun run{spec, options, machine, report, options.out_dir};

  auto intrinsics = MeasureIntrinsics(run, *previous);
  if (!intrinsics.ok()) return finish(intrinsics.status());
  auto camera_from_galvo = AlignCameraToGalvo(run, *intrinsics, *previous);
  if (!camera_from_galvo.ok()) return finish(camera_from_galvo.status());
  calib::HeightLookup lookup;
  if (spec.height) {
    const Status exposed = machine.camera->SetExposure(spec.height_exposure_ms * 1e3);
    if (!exposed.ok()) return finish(PhaseFailure(exposed, "height calibration: "));
    auto heights = CalibrateHeights(run);
    if (!heights.ok()) return finish(heights.status());
    lookup = std::move(*heights);
  }

  calib::CalibrationSet set = *previous;
  set.height_lookup = lookup;
  set.produced_by = "calibrate job " + job.path;
  set.created = report.started;
  set.camera = *intrinsics;
  set.galvo.camera_from_galvo = *camera_from_galvo;
  return finish(Save(run, set));
}

}  // namespace insitu::job
