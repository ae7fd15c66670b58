#include "insitu/job/scan.h"

#include <chrono>
#include <cmath>

#include "insitu/geometry/triangulation.h"

namespace insitu::job {

Status ScanOptions::Validate() const {
  for (double v : {x_start_mm, x_end_mm, y_start_mm, y_end_mm, focus_z_mm}) {
    if (!std::isfinite(v)) return InvalidArgument("x_start_mm must be finite (all positions)");
  }
  if (!(line_spacing_mm > 0)) {
    return InvalidArgument("line_spacing_mm must be > 0, got " + std::to_string(line_spacing_mm));
  }
  if (!(x_end_mm >= x_start_mm)) {
    return InvalidArgument("x_end_mm must be >= x_start_mm, got " + std::to_string(x_end_mm));
  }
  if (line_count() > 100000) {
    return InvalidArgument("line_spacing_mm gives " + std::to_string(line_count()) +
                           " lines, more than 100000");
  }
  if (!(std::abs(y_end_mm - y_start_mm) > 0.1)) {
    return InvalidArgument("y_end_mm must differ from y_start_mm by more than 0.1 mm");
  }
  if (!(speed_mm_per_s > 0)) {
    return InvalidArgument("speed_mm_per_s must be > 0, got " + std::to_string(speed_mm_per_s));
  }
  if (!(settle_ms >= 0)) return InvalidArgument("settle_ms must be >= 0");
  if (!(exposure_ms > 0)) {
    return InvalidArgument("exposure_ms must be > 0, got " + std::to_string(exposure_ms));
  }
  if (!(gain_db >= 0)) return InvalidArgument("gain_db must be >= 0, got " + std::to_string(gain_db));
  if (method != 1 && method != 2) {
    return InvalidArgument("method must be 1 or 2, got " + std::to_string(method));
  }
  if (binning != 1 && binning != 2 && binning != 4) {
    return InvalidArgument("binning must be 1, 2 or 4, got " + std::to_string(binning));
  }
  return Status::Ok();
}

int ScanOptions::line_count() const {
  if (!(line_spacing_mm > 0) || x_end_mm < x_start_mm) return 0;
  return static_cast<int>(std::floor((x_end_mm - x_start_mm) / line_spacing_mm + 1e-9)) + 1;
}

namespace {

// Which way the stripe of a line runs in the image, from the calibration: project both ends.
vision::StripeDirection ExpectedDirection(const calib::CalibrationSet& cal,
                                          const calib::CameraIntrinsics& cam,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector2d pb = cam.Project(cal.galvo.camera_from_galvo * b);
  const Eigen::Vector2d pc = cam.Project(cal.galvo.camera_from_galvo * c);
  const Eigen::Vector2d d = pc - pb;
  return std::abs(d.x()) >= std::abs(d.y()) ? vision::StripeDirection::kColumns
                                            : vision::StripeDirection::kRows;
}

}  // namespace

struct FrameProcessor::Impl {
  ScanOptions options;
  vision::StripeOptions stripe_options;
  calib::CalibrationSet calibration;
  calib::CameraIntrinsics cam;
  Eigen::Isometry3d galvo_from_camera;
  std::unique_ptr<vision::StripeExtractor> extractor;  // for frames of extractor_bit_depth
  int extractor_bit_depth = 0;
  vision::StripeResult stripe;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<int> index;
};

Result<std::unique_ptr<FrameProcessor>> FrameProcessor::Create(
    const ScanOptions& options, const vision::StripeOptions& stripe,
    const calib::CalibrationSet& calibration) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  INSITU_RETURN_IF_ERROR(stripe.Validate());
  if (options.method == 2 && calibration.height_lookup.empty()) {
    return FailedPrecondition("method 2 needs a height lookup in the calibration file: run the "
                              "calibrate job with its height step");
  }
  std::unique_ptr<FrameProcessor> p(new FrameProcessor());
  p->impl_ = std::make_unique<Impl>();
  Impl& m = *p->impl_;
  m.options = options;
  m.calibration = calibration;
  m.cam = calibration.camera.Binned(options.binning);
  m.galvo_from_camera = calibration.galvo.camera_from_galvo.inverse();
  m.stripe_options = stripe;
  if (m.stripe_options.direction == vision::StripeDirection::kAuto) {
    const double x = options.line_x(0);
    m.stripe_options.direction =
        ExpectedDirection(calibration, m.cam, Eigen::Vector3d(x, options.y_start_mm, 0.0),
                          Eigen::Vector3d(x, options.y_end_mm, 0.0));
  }
  return p;
}

FrameProcessor::~FrameProcessor() = default;

Status FrameProcessor::Process(const Frame& frame, int i, ScanOutput* out) {
  Impl& m = *impl_;
  const ScanOptions& options = m.options;
  const calib::CalibrationSet& calibration = m.calibration;
  const double x = options.line_x(i);
  const Eigen::Vector3d from(x, options.y_start_mm, options.focus_z_mm);
  const Eigen::Vector3d to(x, options.y_end_mm, options.focus_z_mm);
  const vision::ImageView view = vision::ViewOf(frame);
  if (!m.extractor || m.extractor_bit_depth != frame.bit_depth) {
    // The scan's gray levels are 8-bit ones: the same light on a 12-bit camera.
    m.extractor = std::make_unique<vision::StripeExtractor>(
        m.stripe_options.ForBitDepth(frame.bit_depth));
    m.extractor_bit_depth = frame.bit_depth;
  }
  const auto t0 = std::chrono::steady_clock::now();
  INSITU_RETURN_IF_ERROR(m.extractor->Extract(view, &m.stripe));
  out->stats.extract_time_ms +=
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const vision::StripeResult& stripe = m.stripe;
  std::vector<Eigen::Vector2d>& pixels = m.pixels;
  std::vector<int>& index = m.index;
  pixels.clear();
  index.clear();
  for (size_t k = 0; k < stripe.status.size(); ++k) {
    ++out->stats.scan_lines_examined;
    switch (stripe.status[k]) {
      case vision::StripeStatus::kValid: ++out->stats.valid; break;
      case vision::StripeStatus::kNone: ++out->stats.none; continue;
      case vision::StripeStatus::kSaturated: ++out->stats.saturated; continue;
      case vision::StripeStatus::kTwoPeaks: ++out->stats.two_peaks; continue;
      case vision::StripeStatus::kTooWide: ++out->stats.too_wide; continue;
    }
    pixels.emplace_back(stripe.u(static_cast<int>(k)), stripe.v(static_cast<int>(k)));
    index.push_back(static_cast<int>(k));
  }
  // Seed 000 eq. (1)-(4): pixel -> normalised ray -> light plane -> galvo frame.
  const std::vector<Eigen::Vector2d> normalized = m.cam.Undistort(pixels);
  // On a measured head the plane follows the pointer's own chief rays (the head's scale,
  // distortion and the pointer's offset included); otherwise the seed's plane through a, b, c.
  // 20 mm: the height range of the parts a scan measures (the lookup's +-15 mm and more).
  const geometry::PlaneInCamera plane = geometry::LineLightPlane(
      calibration, from, to, 20.0, calibration.galvo.camera_from_galvo);
  for (size_t k = 0; k < normalized.size(); ++k) {
    const auto p_cam = geometry::IntersectRayWithPlane(normalized[k], plane);
    if (!p_cam) {
      ++out->stats.rejected_geometry;
      continue;
    }
    Eigen::Vector3d point = m.galvo_from_camera * *p_cam;
    geometry::CloudPoint cp;
    cp.intensity = static_cast<float>(stripe.peak[index[k]] - stripe.base[index[k]]);
    cp.line = i;
    cp.pixel_u = static_cast<float>(pixels[k].x());
    cp.pixel_v = static_cast<float>(pixels[k].y());
    if (options.method == 2) {
      cp.point_in_galvo = point.cast<float>();
      out->cloud_method1.push_back(cp);
      // Seed 000 method 2: the height from the lookup, the point where this pixel's ray
      // reaches that height.
      const double b = options.binning;
      const auto h = calibration.height_lookup.Height(x, (pixels[k].x() + 0.5) * b - 0.5,
                                                      (pixels[k].y() + 0.5) * b - 0.5);
      if (!h) {
        ++out->stats.outside_lookup;
        continue;
      }
      const Eigen::Vector3d origin = m.galvo_from_camera.translation();
      const Eigen::Vector3d dir = m.galvo_from_camera.linear() *
                                  Eigen::Vector3d(normalized[k].x(), normalized[k].y(), 1.0);
      point = origin + dir * ((*h - origin.z()) / dir.z());
    }
    cp.point_in_galvo = point.cast<float>();
    out->cloud.push_back(cp);
  }
  ++out->stats.lines;
  return Status::Ok();
}

Result<ScanOutput> RunScan(hw::Machine& machine, const ScanOptions& options,
                           const vision::StripeOptions& stripe_options,
                           const calib::CalibrationSet& calibration,
                           const std::function<void(int, int)>& progress,
                           const std::atomic<bool>* cancel) {
  INSITU_ASSIGN_OR_RETURN(std::unique_ptr<FrameProcessor> processor,
                          FrameProcessor::Create(options, stripe_options, calibration));
  const hw::CameraInfo info = machine.camera->info();
  INSITU_RETURN_IF_ERROR(calib::CheckCameraMatches(calibration.camera, info.model, info.serial,
                                                   info.sensor_width_px,
                                                   info.sensor_height_px));
  INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(options.exposure_ms * 1e3));
  INSITU_RETURN_IF_ERROR(machine.camera->SetGain(options.gain_db));
  INSITU_RETURN_IF_ERROR(machine.camera->SetBinning(options.binning));

  struct PointerGuard {  // the pointer never keeps running after the scan, whatever happens
    hw::Scanner* s;
    ~PointerGuard() { (void)s->StopPointer(); }
  } guard{machine.scanner.get()};

  ScanOutput out;
  const int lines = options.line_count();
  const double t_start = machine.clock->Now();
  for (int i = 0; i < lines; ++i) {
    if (cancel && cancel->load()) return Status(StatusCode::kCancelled, "scan cancelled");
    const double x = options.line_x(i);
    const Eigen::Vector3d from(x, options.y_start_mm, options.focus_z_mm);
    const Eigen::Vector3d to(x, options.y_end_mm, options.focus_z_mm);
    INSITU_RETURN_IF_ERROR(machine.scanner->StartPointerLine(from, to, options.speed_mm_per_s)
                               .Prefixed("line " + std::to_string(i)));
    machine.clock->SleepFor(options.settle_ms * 1e-3);
    auto frame = machine.camera->Grab();
    if (!frame.ok()) return frame.status().Prefixed("line " + std::to_string(i) + ": camera");
    INSITU_RETURN_IF_ERROR(processor->Process(*frame, i, &out));
    if (progress) progress(i + 1, lines);
  }
  out.stats.machine_time_s = machine.clock->Now() - t_start;
  return out;
}

}  // namespace insitu::job
