#include "insitu/job/scan.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "insitu/geometry/triangulation.h"
#include "insitu/vision/background.h"
#include "insitu/vision/canvas.h"
#include "insitu/vision/image_io.h"

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
  if (!(std::isfinite(height_range_mm[0]) && std::isfinite(height_range_mm[1]) &&
        height_range_mm[1] > height_range_mm[0])) {
    return InvalidArgument("height_range_mm must be [low, high] with high > low");
  }
  if (background_frames < 0 || background_frames > 64) {
    return InvalidArgument("background_frames must be in [0, 64], got " +
                           std::to_string(background_frames));
  }
  if (!(min_stripe_fraction >= 0 && min_stripe_fraction <= 1)) {
    return InvalidArgument("min_stripe_fraction must be in [0, 1]");
  }
  if (queue_frames < 1 || queue_frames > 1000) {
    return InvalidArgument("queue_frames must be in 1..1000, got " + std::to_string(queue_frames));
  }
  return Status::Ok();
}

int ScanOptions::line_count() const {
  if (!(line_spacing_mm > 0) || x_end_mm < x_start_mm) return 0;
  return static_cast<int>(std::floor((x_end_mm - x_start_mm) / line_spacing_mm + 1e-9)) + 1;
}

namespace {

// The extraction's options with kAuto resolved: which way the stripe of the scan's lines
// runs in the (binned) image, from the calibration, the first line's ends projected.
vision::StripeOptions Resolved(const vision::StripeOptions& stripe, const ScanOptions& o,
                               const calib::CalibrationSet& cal) {
  vision::StripeOptions out = stripe;
  if (out.direction != vision::StripeDirection::kAuto) return out;
  const calib::CameraIntrinsics cam = cal.camera.Binned(o.binning);
  const double x = o.line_x(0);
  const Eigen::Vector2d pb =
      cam.Project(cal.galvo.camera_from_galvo * Eigen::Vector3d(x, o.y_start_mm, 0.0));
  const Eigen::Vector2d pc =
      cam.Project(cal.galvo.camera_from_galvo * Eigen::Vector3d(x, o.y_end_mm, 0.0));
  const Eigen::Vector2d d = pc - pb;
  out.direction = std::abs(d.x()) >= std::abs(d.y()) ? vision::StripeDirection::kColumns
                                                     : vision::StripeDirection::kRows;
  return out;
}

// The point of a light plane (camera frame coefficients) at galvo (y, z): the sheet's x there;
// a plane parallel to x (none in practice): `x_fallback`.
Eigen::Vector3d SheetPoint(const Eigen::Vector4d& plane_in_camera,
                           const Eigen::Isometry3d& camera_from_galvo, double y, double z,
                           double x_fallback) {
  // The plane in the galvo frame: n . p + d = 0 with p = (x, y, z).
  const Eigen::Vector3d n = camera_from_galvo.linear().transpose() * plane_in_camera.head<3>();
  const double d =
      plane_in_camera.head<3>().dot(camera_from_galvo.translation()) + plane_in_camera(3);
  const double x = std::abs(n.x()) > 1e-9 ? -(n.y() * y + n.z() * z + d) / n.x() : x_fallback;
  return Eigen::Vector3d(x, y, z);
}

// Where line i's stripe can lie in a frame (binned pixels, the frame's region at offset_x,
// offset_y): its light plane over the height range, along the line, projected: per scan line of
// the extraction's direction, the span between the plane's cuts at the range's two heights,
// plus a margin for the pointer's landing off the calibrated plane on a real head (a few
// 0.1 mm: 8 full-sensor pixels) and the stripe's half width. A reflection or a lit surface
// outside it is never the stripe.
vision::StripeWindow LineWindowOnPlane(const ScanOptions& o, const calib::CalibrationSet& cal,
                                       const calib::CameraIntrinsics& cam,
                                       vision::StripeDirection dir, int i, int width, int height,
                                       int offset_x, int offset_y,
                                       const geometry::PlaneInCamera& plane) {
  const bool columns = dir == vision::StripeDirection::kColumns;
  const int lines = columns ? width : height;
  vision::StripeWindow window;
  window.lo.assign(static_cast<size_t>(lines), std::numeric_limits<float>::infinity());
  window.hi.assign(static_cast<size_t>(lines), -std::numeric_limits<float>::infinity());
  const Eigen::Isometry3d& camera_from_galvo = cal.galvo.camera_from_galvo;
  const double margin = 2.0 + 8.0 / o.binning;
  constexpr int kSamples = 200;
  auto corner = [&](int k, double z) -> std::optional<Eigen::Vector2d> {
    const double y = o.y_start_mm + (o.y_end_mm - o.y_start_mm) * k / kSamples;
    const Eigen::Vector3d p =
        camera_from_galvo * SheetPoint(plane.coeffs, camera_from_galvo, y, z, o.line_x(i));
    if (!(p.z() > 0)) return std::nullopt;
    return cam.Project(p) - Eigen::Vector2d(offset_x, offset_y);
  };
  for (int k = 0; k < kSamples; ++k) {
    // The patch of the sheet between y_k and y_k+1 over the height range, as a box.
    double umin = INFINITY, umax = -INFINITY, vmin = INFINITY, vmax = -INFINITY;
    bool seen = false;
    for (int kk : {k, k + 1}) {
      for (double z : {o.height_range_mm[0], o.height_range_mm[1]}) {
        const auto px = corner(kk, z);
        if (!px) continue;
        seen = true;
        umin = std::min(umin, px->x()), umax = std::max(umax, px->x());
        vmin = std::min(vmin, px->y()), vmax = std::max(vmax, px->y());
      }
    }
    if (!seen) continue;
    const double line_lo = (columns ? umin : vmin) - margin,
                 line_hi = (columns ? umax : vmax) + margin;
    const double along_lo = (columns ? vmin : umin) - margin,
                 along_hi = (columns ? vmax : umax) + margin;
    // Clamped to the frame before the casts (a point far outside projects anywhere).
    const int first = static_cast<int>(std::floor(std::clamp(line_lo, 0.0, lines - 1.0)));
    const int last = static_cast<int>(std::ceil(std::clamp(line_hi, 0.0, lines - 1.0)));
    if (!(line_hi >= 0.0 && line_lo <= lines - 1.0)) continue;
    for (int l = first; l <= last; ++l) {
      window.lo[l] = std::min(window.lo[l], static_cast<float>(along_lo));
      window.hi[l] = std::max(window.hi[l], static_cast<float>(along_hi));
    }
  }
  // Scan lines the sheet never crosses: no stripe can be there (lo > hi).
  return window;
}

}  // namespace

namespace {

// line_NNNN.png: the frame (a mosaic's raw samples; none for RGB); line_NNNN_stripe.png: the plane
// the extraction read over the span of its window, with the window (blue), its valid centres
// (green) and, just above the window, each refused scan line's status (red saturated, magenta two
// peaks, orange too wide, yellow bad shape).
Status SaveLineFrames(const std::string& dir, int i, const vision::ImageView& frame,
                      const vision::ImageView& plane, const vision::StripeResult& stripe,
                      const vision::StripeWindow& window) {
  char name[32];
  std::snprintf(name, sizeof(name), "line_%04d", i);
  const std::filesystem::path base = std::filesystem::path(dir) / name;
  // A mosaic as its raw samples (what the sensor gave); a three-sample frame only as the plane
  // below.
  vision::ImageView raw = frame;
  if (IsBayer(raw.format)) raw.format = PixelFormat::kMono;
  if (raw.format == PixelFormat::kMono) {
    INSITU_RETURN_IF_ERROR(vision::WritePng(base.string() + ".png", raw));
  }
  INSITU_ASSIGN_OR_RETURN(vision::Canvas canvas, vision::Canvas::FromGray(plane));
  const bool columns = stripe.direction == vision::StripeDirection::kColumns;
  auto dot = [&](double along_line, double across, int rgb) {
    const Eigen::Vector2d p =
        columns ? Eigen::Vector2d(along_line, across) : Eigen::Vector2d(across, along_line);
    canvas.Line(p, p, vision::Pen{rgb, 1, false});
  };
  for (size_t k = 0; k < stripe.status.size(); ++k) {
    const double line = static_cast<double>(k);
    if (k < window.lo.size() && window.lo[k] <= window.hi[k]) {
      dot(line, window.lo[k], 0x3060FF);
      dot(line, window.hi[k], 0x3060FF);
    }
    int rgb = -1;
    switch (stripe.status[k]) {
      case vision::StripeStatus::kValid:
        dot(line, stripe.center[k], 0x00FF00);
        break;
      case vision::StripeStatus::kNone:
        break;
      case vision::StripeStatus::kSaturated:
        rgb = 0xFF0000;
        break;
      case vision::StripeStatus::kTwoPeaks:
        rgb = 0xFF00FF;
        break;
      case vision::StripeStatus::kTooWide:
        rgb = 0xFF8000;
        break;
      case vision::StripeStatus::kBadShape:
        rgb = 0xFFFF00;
        break;
    }
    if (rgb >= 0) {  // just outside the window, or along the frame's edge
      const bool in = k < window.lo.size() && window.lo[k] <= window.hi[k];
      const double at = in ? std::max(0.0, window.lo[k] - 10.0) : 0.0;
      for (int edge = 0; edge < 4; ++edge) dot(line, at + edge, rgb);
    }
  }
  // The picture of the window's span (the rows the stripe may occupy, a margin around them).
  int first = -1, last = -1;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t k = 0; k < window.lo.size(); ++k) {
    if (!(window.lo[k] <= window.hi[k])) continue;
    if (first < 0) first = static_cast<int>(k);
    last = static_cast<int>(k);
    lo = std::min(lo, window.lo[k]);
    hi = std::max(hi, window.hi[k]);
  }
  if (first >= 0) {
    constexpr int kMargin = 16;
    const int lines = columns ? canvas.width() : canvas.height();
    const int across = columns ? canvas.height() : canvas.width();
    const int l0 = std::max(0, first - kMargin), l1 = std::min(lines, last + 1 + kMargin);
    const int a0 = std::clamp(static_cast<int>(std::floor(lo)) - kMargin, 0, across);
    const int a1 = std::clamp(static_cast<int>(std::ceil(hi)) + 1 + kMargin, 0, across);
    if (l1 > l0 && a1 > a0) {
      const vision::Canvas span = columns ? canvas.Region(l0, a0, l1 - l0, a1 - a0)
                                          : canvas.Region(a0, l0, a1 - a0, l1 - l0);
      return span.WritePng(base.string() + "_stripe.png");
    }
  }
  return canvas.WritePng(base.string() + "_stripe.png");
}

}  // namespace

vision::StripeWindow LineStripeWindow(const ScanOptions& o, const calib::CalibrationSet& cal,
                                      vision::StripeDirection direction, int i, int width,
                                      int height, int offset_x, int offset_y) {
  const Eigen::Vector3d from(o.line_x(i), o.y_start_mm, o.focus_z_mm);
  const Eigen::Vector3d to(o.line_x(i), o.y_end_mm, o.focus_z_mm);
  const geometry::PlaneInCamera plane =
      geometry::LineLightPlane(cal, from, to, 20.0, cal.galvo.camera_from_galvo);
  return LineWindowOnPlane(o, cal, cal.camera.Binned(o.binning), direction, i, width, height,
                           offset_x, offset_y, plane);
}

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
  vision::Image background;  // empty: none
  vision::Image subtracted;  // the frame less the background, reused
  vision::Image plane;       // a colour frame reduced to the pointer's channel, reused
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
  m.stripe_options = Resolved(stripe, options, calibration);
  return p;
}

FrameProcessor::~FrameProcessor() = default;

void FrameProcessor::SetBackground(vision::Image background) {
  impl_->background = std::move(background);
}

Status FrameProcessor::Process(const Frame& frame, int i, ScanOutput* out) {
  Impl& m = *impl_;
  const ScanOptions& options = m.options;
  const calib::CalibrationSet& calibration = m.calibration;
  const double x = options.line_x(i);
  const Eigen::Vector3d from(x, options.y_start_mm, options.focus_z_mm);
  const Eigen::Vector3d to(x, options.y_end_mm, options.focus_z_mm);
  vision::ImageView view = vision::ViewOf(frame);
  if (!m.background.bytes.empty()) {
    const Status subtracted =
        vision::SubtractBackground(view, m.background.view(), &m.subtracted,
                                   m.stripe_options.saturation_level);
    if (!subtracted.ok()) return subtracted.Prefixed("line " + std::to_string(i));
    view = m.subtracted.view();
  }
  // A colour camera: the pointer's channel (the room's light subtracted sample by sample first).
  auto channel = vision::StripePlane(view, m.stripe_options.colour_channel, &m.plane);
  if (!channel.ok()) return channel.status().Prefixed("line " + std::to_string(i));
  view = *channel;
  if (!m.extractor || m.extractor_bit_depth != frame.bit_depth) {
    // The scan's gray levels are 8-bit ones: the same light on a 12-bit camera.
    m.extractor = std::make_unique<vision::StripeExtractor>(
        m.stripe_options.ForBitDepth(frame.bit_depth));
    m.extractor_bit_depth = frame.bit_depth;
  }
  // Seed 000 eq. (1)-(4): pixel -> normalised ray -> light plane -> galvo frame. On a measured
  // head the plane follows the pointer's own chief rays (the head's scale, distortion and the
  // pointer's offset included); otherwise the seed's plane through a, b, c. 20 mm: the height
  // range of the parts a scan measures (the lookup's +-15 mm and more).
  const geometry::PlaneInCamera plane =
      geometry::LineLightPlane(calibration, from, to, 20.0, calibration.galvo.camera_from_galvo);
  const vision::StripeWindow window =
      LineWindowOnPlane(options, calibration, m.cam, m.stripe_options.direction, i, frame.width,
                        frame.height, frame.offset_x, frame.offset_y, plane);
  const auto t0 = std::chrono::steady_clock::now();
  INSITU_RETURN_IF_ERROR(m.extractor->Extract(view, &m.stripe, &window));
  out->stats.extract_time_ms +=
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!options.frames_dir.empty()) {
    INSITU_RETURN_IF_ERROR(
        SaveLineFrames(options.frames_dir, i, vision::ViewOf(frame), view, m.stripe, window));
  }
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
      case vision::StripeStatus::kBadShape:
        ++out->stats.bad_shape;
        continue;
    }
    // On the (binned) sensor: a region's frame starts at its offset.
    pixels.emplace_back(stripe.u(static_cast<int>(k)) + frame.offset_x,
                        stripe.v(static_cast<int>(k)) + frame.offset_y);
    index.push_back(static_cast<int>(k));
  }
  const std::vector<Eigen::Vector2d> normalized = m.cam.Undistort(pixels);
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
    cp.center_sigma_px = stripe.sigma_px[index[k]];
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

namespace {

// Frames taken, waiting for the processing thread: bounded, never dropping one.
class FrameQueue {
 public:
  explicit FrameQueue(int capacity) : capacity_(capacity) {}
  // False when full (the caller stops the scan: a line is never dropped).
  bool Push(int line, Frame frame) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (static_cast<int>(frames_.size()) >= capacity_) return false;
    frames_.emplace_back(line, std::move(frame));
    max_size_ = std::max(max_size_, static_cast<int>(frames_.size()));
    wake_.notify_all();
    return true;
  }
  // The next frame; nothing once closed and empty.
  std::optional<std::pair<int, Frame>> Pop() {
    std::unique_lock<std::mutex> lock(mutex_);
    wake_.wait(lock, [this] { return !frames_.empty() || closed_; });
    if (frames_.empty()) return std::nullopt;
    auto next = std::move(frames_.front());
    frames_.pop_front();
    return next;
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    wake_.notify_all();
  }
  int max_size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return max_size_;
  }

 private:
  const int capacity_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::pair<int, Frame>> frames_;
  bool closed_ = false;
  int max_size_ = 0;
};

// The band of full-sensor rows where the stripe of any line can lie for a surface within the
// height range: for each line, the points of its light plane (the plane the scan triangulates
// with, leaning away from the vertical as |x| grows: ~0.2 mm per mm of height at x = 60 mm)
// at the range's heights along the line, projected through the calibration. The margin: the
// widest stripe the extraction accepts, the median's and the background's reach (3 rows
// beyond the run), and the pointer's landing off the plane on a real head (a few 0.1 mm,
// ~4 px), in full-sensor pixels.
std::pair<int, int> StripeBand(const ScanOptions& o, const vision::StripeOptions& stripe,
                               const calib::CalibrationSet& cal) {
  const calib::CameraIntrinsics& cam = cal.camera;
  const Eigen::Isometry3d& camera_from_galvo = cal.galvo.camera_from_galvo;
  const double z_reach = std::max(std::abs(o.height_range_mm[0]), std::abs(o.height_range_mm[1]));
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  const int lines = o.line_count();
  for (int i = 0; i < lines; ++i) {
    const Eigen::Vector3d from(o.line_x(i), o.y_start_mm, o.focus_z_mm);
    const Eigen::Vector3d to(o.line_x(i), o.y_end_mm, o.focus_z_mm);
    const Eigen::Vector4d plane =
        geometry::LineLightPlane(cal, from, to, z_reach, camera_from_galvo).coeffs;
    for (int k = 0; k <= 20; ++k) {
      const double y = o.y_start_mm + (o.y_end_mm - o.y_start_mm) * k / 20.0;
      for (int j = 0; j <= 4; ++j) {
        const double z = o.height_range_mm[0] + (o.height_range_mm[1] - o.height_range_mm[0]) * j / 4.0;
        const Eigen::Vector3d p =
            camera_from_galvo * SheetPoint(plane, camera_from_galvo, y, z, o.line_x(i));
        if (!(p.z() > 0)) continue;
        const Eigen::Vector2d px = cam.Project(p);
        if (!(px.x() >= 0 && px.x() < cam.width_px)) continue;
        lo = std::min(lo, px.y());
        hi = std::max(hi, px.y());
      }
    }
  }
  if (!(hi >= lo)) return {0, 0};  // nothing in view: the whole sensor
  const double margin = (stripe.max_width_px + 2.0 * stripe.median_kernel + 3.0) * o.binning + 8.0;
  const int first = std::clamp(static_cast<int>(std::floor(lo - margin)), 0, cam.height_px);
  const int last = std::clamp(static_cast<int>(std::ceil(hi + margin)), 0, cam.height_px);
  if (last - first >= cam.height_px) return {0, 0};
  return {first, last - first};
}

}  // namespace

double EvenSweepSpeed(double speed, double length_mm, double exposure_ms) {
  if (!(length_mm > 0) || !(exposure_ms > 0) || !(speed > 0)) return speed;
  const double period_ms = 2e3 * length_mm / speed;
  const double periods = std::max(1.0, std::round(exposure_ms / period_ms));
  const double even = 2e3 * length_mm * periods / exposure_ms;
  return even <= 4.0 * speed ? even : speed;
}

namespace {

double LineLength(const ScanOptions& o) { return std::abs(o.y_end_mm - o.y_start_mm); }

// Stops the pointer when it goes out of scope: a scan's way out, whichever it takes.
struct PointerOff {
  hw::Scanner* scanner;
  ~PointerOff() { (void)scanner->StopPointer(); }
};

// The stripe's brightness target for auto exposure: the 98th percentile of the lit columns'
// peaks at 55 % of full scale. The peaks are the filtered profile's (3x3 median); saturation
// is the raw pixels', which speckle (contrast ~0.2 at a point, grains about a binned pixel)
// lifts above them, and the lines between the pre-shot ones may be brighter (a crown, a
// steeper face toward the camera): 45 % of headroom keeps those below saturation, and 55 % of
// full scale is still 140 levels of an 8-bit camera, far above the extraction's thresholds.
constexpr double kExposureTarget = 0.55;
constexpr double kExposurePercentile = 0.98;

}  // namespace

Result<double> AutoExpose(hw::Machine& machine, const ScanOptions& options,
                          const vision::StripeOptions& stripe_options,
                          const calib::CalibrationSet& calibration,
                          const std::atomic<bool>* cancel, int* shots, std::string* note) {
  const int n = options.line_count();
  std::vector<int> probe{0};
  if (n > 2) probe.push_back(n / 2);
  if (n > 1) probe.push_back(n - 1);
  const vision::StripeOptions so = Resolved(stripe_options, options, calibration);
  std::unique_ptr<vision::StripeExtractor> extractor;
  int extractor_bits = 0;
  vision::StripeResult stripe;
  vision::Image plane;  // a colour frame in the pointer's channel
  const PointerOff pointer_off{machine.scanner.get()};
  double exposure_ms = options.exposure_ms;
  const double kMinMs = 0.02, kMaxMs = std::min(1000.0, 8.0 * options.exposure_ms);
  double too_dark = 0.0;                                      // the most with no stripe
  double too_bright = std::numeric_limits<double>::infinity();  // the least that saturated
  double measured = -1.0;  // the exposure the last measured level asked for
  bool converged = false;
  // The last round whose level saturated: its exposure, valid columns' peaks and saturated
  // columns; and the saturated columns excused as glints (0 until a cut shows them).
  struct {
    double exposure_ms = 0.0;
    std::vector<double> peaks;
    int64_t glinting = 0;
  } last_saturated;
  int64_t glints = 0;
  for (int round = 0; round < 8; ++round) {
    if (cancel && cancel->load()) return Status(StatusCode::kCancelled, "scan cancelled");
    INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(exposure_ms * 1e3).Prefixed("auto exposure"));
    std::vector<double> peaks;
    int64_t saturated = 0;
    int max_value = 255;
    for (int i : probe) {
      const double x = options.line_x(i);
      INSITU_RETURN_IF_ERROR(machine.scanner->StartPointerLine(
          Eigen::Vector3d(x, options.y_start_mm, options.focus_z_mm),
          Eigen::Vector3d(x, options.y_end_mm, options.focus_z_mm),
          EvenSweepSpeed(options.speed_mm_per_s, LineLength(options), exposure_ms)));
      machine.clock->SleepFor(options.settle_ms * 1e-3);
      auto frame = machine.camera->Grab();
      if (!frame.ok()) return frame.status().Prefixed("auto exposure: camera");
      ++*shots;
      if (!extractor || extractor_bits != frame->bit_depth) {
        extractor = std::make_unique<vision::StripeExtractor>(so.ForBitDepth(frame->bit_depth));
        extractor_bits = frame->bit_depth;
      }
      max_value = frame->max_value();
      INSITU_ASSIGN_OR_RETURN(
          const vision::ImageView view,
          vision::StripePlane(vision::ViewOf(*frame), so.colour_channel, &plane));
      INSITU_RETURN_IF_ERROR(extractor->Extract(view, &stripe));
      for (size_t k = 0; k < stripe.status.size(); ++k) {
        if (stripe.status[k] == vision::StripeStatus::kValid) peaks.push_back(stripe.peak[k]);
        if (stripe.status[k] == vision::StripeStatus::kSaturated) ++saturated;
      }
    }
    (void)machine.scanner->StopPointer();
    const auto valid = static_cast<int64_t>(peaks.size());
    // Glints: a specular part mirrors the pointer into the camera tens of times brighter than
    // its diffuse stripe. When a cut of the exposure by 2 or more left most saturated columns
    // saturated (each then above twice full scale: over 3.6 times the target) and lost a tenth
    // or more of the valid ones to the dark, no exposure measures both (the camera's range is
    // full scale over min_peak, ~12): the columns still saturated are excused as glints, and
    // the level is the rest's, from the round before the cut (its valid columns still seen;
    // the columns saturated there but not after the cut count at full scale).
    const auto before = static_cast<int64_t>(last_saturated.peaks.size());
    if (glints == 0 && last_saturated.exposure_ms >= 2.0 * exposure_ms &&
        last_saturated.glinting >= 10 && before >= 10 && 2 * saturated >= last_saturated.glinting &&
        10 * valid < 9 * before) {
      glints = saturated;
      too_bright = std::numeric_limits<double>::infinity();
      too_dark = 0.0;
      exposure_ms = last_saturated.exposure_ms;
      peaks = std::move(last_saturated.peaks);
      saturated = last_saturated.glinting;
    }
    const std::vector<double> valid_peaks = peaks;
    // Saturated columns are the brightest: they count at full scale (but for the glints).
    peaks.insert(peaks.end(), static_cast<size_t>(std::max<int64_t>(0, saturated - glints)),
                 static_cast<double>(max_value));
    double next = exposure_ms;
    const auto between = [&] { return std::sqrt(too_dark * too_bright); };
    if (peaks.size() < 10) {  // no stripe to speak of
      too_dark = std::max(too_dark, exposure_ms);
      next = std::isfinite(too_bright) ? between() : exposure_ms * 4.0;
    } else {
      const size_t k = static_cast<size_t>(kExposurePercentile * (peaks.size() - 1));
      std::nth_element(peaks.begin(), peaks.begin() + static_cast<ptrdiff_t>(k), peaks.end());
      if (peaks[k] >= max_value) {  // the percentile itself saturates: its level is unknown
        too_bright = std::min(too_bright, exposure_ms);
        next = too_dark > 0 ? between() : exposure_ms / 3.0;
        last_saturated = {exposure_ms, valid_peaks, saturated};
      } else {
        const double factor = kExposureTarget * max_value / std::max(peaks[k], 1.0);
        next = std::clamp(exposure_ms * factor, kMinMs, kMaxMs);
        measured = next;
        if (std::abs(factor - 1.0) < 0.15) {
          exposure_ms = next;
          converged = true;
          break;
        }
      }
    }
    next = std::clamp(next, kMinMs, kMaxMs);
    if (next == exposure_ms) break;  // at the camera's or the scan's limit
    exposure_ms = next;
  }
  if (!converged) {
    if (measured > 0) {
      *note = "auto exposure did not settle in its pre-shots: " + std::to_string(measured) +
              " ms, from the last stripe level it measured";
      exposure_ms = measured;
    } else if (std::isfinite(too_bright)) {
      *note = "auto exposure: the stripe saturated down to " + std::to_string(too_bright) +
              " ms; " + std::to_string(exposure_ms) + " ms is unmeasured";
    } else {
      *note = "auto exposure found no stripe in its pre-shots up to " +
              std::to_string(too_dark) + " ms (no part under the first, middle and last lines?): " +
              "kept the job's " + std::to_string(options.exposure_ms) + " ms";
      exposure_ms = options.exposure_ms;
    }
  }
  if (glints > 0) {
    *note += std::string(note->empty() ? "" : "; ") +
             "auto exposure set for the stripe's diffuse light: " + std::to_string(glints) +
             " columns of the pre-shots stayed saturated at half the exposure or less (glints of "
             "a specular surface), and their centres are lost at any exposure that shows the rest";
  }
  INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(exposure_ms * 1e3).Prefixed("auto exposure"));
  return exposure_ms;
}

namespace {

// The room's light as the scan's frames will see it (the exposure, gain and region already
// set), handed to `processor`.
Status TakeBackground(hw::Machine& machine, int frames, const std::atomic<bool>* cancel,
                      FrameProcessor* processor, ScanStats* stats) {
  INSITU_ASSIGN_OR_RETURN(vision::Image mean, GrabBackground(machine, frames, cancel));
  double level = 0.0;
  const vision::ImageView mv = mean.view();
  for (int v = 0; v < mv.height; ++v) {
    for (int u = 0; u < mv.width; ++u) level += mv.is_8bit() ? mv.row8(v)[u] : mv.row16(v)[u];
  }
  stats->background_frames = frames;
  stats->background_level = level / (static_cast<double>(mv.width) * mv.height);
  processor->SetBackground(std::move(mean));
  return Status::Ok();
}

// Columns (rows, for a stripe across rows) the lines span in the binned image at the focus
// height: what a surface under the whole of every line would light.
int64_t ExpectedColumns(const ScanOptions& o, const vision::StripeOptions& stripe,
                        const calib::CalibrationSet& cal) {
  const calib::CameraIntrinsics cam = cal.camera.Binned(o.binning);
  int64_t total = 0;
  for (int i = 0; i < o.line_count(); ++i) {
    const Eigen::Vector3d a = cal.galvo.camera_from_galvo *
                              Eigen::Vector3d(o.line_x(i), o.y_start_mm, o.focus_z_mm);
    const Eigen::Vector3d b = cal.galvo.camera_from_galvo *
                              Eigen::Vector3d(o.line_x(i), o.y_end_mm, o.focus_z_mm);
    if (!(a.z() > 0 && b.z() > 0)) continue;
    const Eigen::Vector2d pa = cam.Project(a), pb = cam.Project(b);
    const bool rows = stripe.direction == vision::StripeDirection::kRows;
    const double lo = std::max(0.0, std::min(rows ? pa.y() : pa.x(), rows ? pb.y() : pb.x()));
    const double hi = std::min(static_cast<double>(rows ? cam.height_px : cam.width_px),
                               std::max(rows ? pa.y() : pa.x(), rows ? pb.y() : pb.x()));
    if (hi > lo) total += static_cast<int64_t>(hi - lo);
  }
  return total;
}

}  // namespace

Result<vision::Image> GrabBackground(hw::Machine& machine, int frames,
                                     const std::atomic<bool>* cancel) {
  INSITU_RETURN_IF_ERROR(machine.scanner->StopPointer().Prefixed("background"));
  std::vector<Frame> grabbed;
  for (int k = 0; k < frames; ++k) {
    if (cancel && cancel->load()) return Status(StatusCode::kCancelled, "cancelled");
    auto frame = machine.camera->Grab();
    if (!frame.ok()) return frame.status().Prefixed("background: camera");
    grabbed.push_back(std::move(*frame));
  }
  std::vector<vision::ImageView> views;
  for (const Frame& f : grabbed) views.push_back(vision::ViewOf(f));
  return vision::AverageFrames(views);
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
  ScanOutput out;
  out.stats.exposure_ms = options.exposure_ms;
  struct RegionGuard {  // the camera reads its whole sensor again after the scan
    hw::Camera* camera;
    bool set = false;
    ~RegionGuard() {
      if (set) (void)camera->SetRegion(0, 0);
    }
  } region_guard{machine.camera.get()};
  out.stats.region_rows = info.sensor_height_px;
  if (options.region) {
    const auto [first, rows] = StripeBand(options, stripe_options, calibration);
    region_guard.set = rows > 0;  // whatever happens next, the camera ends whole
    const Status set = machine.camera->SetRegion(first, rows);
    if (set.ok()) {
      out.stats.region_first_row = first;
      if (rows > 0) out.stats.region_rows = rows;
    } else if (set.code() == StatusCode::kFailedPrecondition) {
      out.stats.region_note = set.message() + ": it reads its whole sensor";
    } else {
      return set.Prefixed("camera region");
    }
  }

  const int lines = options.line_count();
  // A camera wired to the head's trigger output exposes on the head's pulses: the head paces
  // the scan, and the lines always stream (the head does not wait for the processing).
  // Refused before any pre-shot is taken.
  const bool triggered = machine.camera->head_triggered();
  if (triggered && !machine.scanner->info().trigger_output) {
    return FailedPrecondition(
        "the camera is triggered by the scan head, but the head has no trigger output "
        "(machine.lmc.trigger_port names the board's output wired to the camera)");
  }
  if (options.auto_exposure) {
    INSITU_ASSIGN_OR_RETURN(out.stats.exposure_ms,
                            AutoExpose(machine, options, stripe_options, calibration, cancel,
                                       &out.stats.auto_exposure_shots,
                                       &out.stats.exposure_note));
  }
  if (options.background_frames > 0) {
    INSITU_RETURN_IF_ERROR(TakeBackground(machine, options.background_frames, cancel,
                                          processor.get(), &out.stats));
  }
  const double sweep_speed =
      EvenSweepSpeed(options.speed_mm_per_s, LineLength(options), out.stats.exposure_ms);
  out.stats.pointer_speed_mm_per_s = sweep_speed;
  const bool streaming = options.streaming || triggered;
  // Streaming: one thread processes the frames in line order while this one takes the next.
  FrameQueue queue(options.queue_frames);
  std::atomic<int> processed{0};
  std::atomic<bool> failed{false};
  Status processing;  // the processing thread's first error (read after it has ended)
  std::thread worker;
  if (streaming) {
    worker = std::thread([&] {
      while (auto next = queue.Pop()) {
        if (!processing.ok()) continue;  // drain: the scan is stopping
        processing = processor->Process(next->second, next->first, &out);
        if (!processing.ok()) failed.store(true);
        processed.fetch_add(1);
      }
    });
  }
  // Ends the processing thread on every way out; its error, if any, first.
  const auto join = [&]() -> Status {
    if (!worker.joinable()) return Status::Ok();
    queue.Close();
    worker.join();
    return processing;
  };
  const auto stop = [&](Status why) {
    const Status joined = join();
    return joined.ok() ? why : joined;
  };
  const auto line_from = [&](int i) {
    return Eigen::Vector3d(options.line_x(i), options.y_start_mm, options.focus_z_mm);
  };
  const auto line_to = [&](int i) {
    return Eigen::Vector3d(options.line_x(i), options.y_end_mm, options.focus_z_mm);
  };
  // Line i's frame to the processing (streaming), or processed here.
  const auto take = [&](int i, Frame frame) -> Status {
    if (streaming) {
      if (!queue.Push(i, std::move(frame))) {
        return DeviceError(
            "line " + std::to_string(i) + ": the processing fell " +
            std::to_string(options.queue_frames) +
            " frames behind the camera (scan.queue_frames); no line was dropped, the scan "
            "stopped: " +
            (triggered ? std::string("slow the lines (scan.settle_ms) or raise queue_frames")
                       : std::string("lower the camera's frame rate or raise queue_frames")));
      }
      return Status::Ok();
    }
    const auto t0 = std::chrono::steady_clock::now();
    INSITU_RETURN_IF_ERROR(processor->Process(frame, i, &out));
    // The next line waits for this one's processing: on a real cell that time passes anyway;
    // a simulated machine's clock is told (MachineClock::Waited).
    machine.clock->Waited(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    processed.store(i + 1);
    return Status::Ok();
  };

  const double t_start = machine.clock->Now();
  if (triggered) {
    hw::TriggeredSweep sweep;
    for (int i = 0; i < lines; ++i) sweep.lines.emplace_back(line_from(i), line_to(i));
    sweep.speed_mm_per_s = options.speed_mm_per_s;
    sweep.settle_s = options.settle_ms * 1e-3;
    // The pointer stays on its line through the whole exposure (0.5 ms beyond it: the
    // camera's exposure starts microseconds after the edge), and pulses come no faster than
    // the camera takes frames, 2 % under its rate for the trigger's own overhead: a pulse
    // while it is still busy would be ignored and the line lost.
    const double rate = machine.camera->max_frame_rate_hz();
    const double period = rate > 0 ? 1.02 / rate : 0.0;
    sweep.dwell_s = std::max(out.stats.exposure_ms * 1e-3 + 0.5e-3, period - sweep.settle_s);
    out.stats.trigger = "head";
    out.stats.pointer_speed_mm_per_s = sweep.speed_mm_per_s;  // the head's own sweep
    INSITU_RETURN_IF_ERROR(machine.camera->StartTriggered().Prefixed("camera trigger"));
    struct TriggerGuard {  // the camera back on software trigger, whatever happens
      hw::Camera* camera;
      ~TriggerGuard() { (void)camera->StopTriggered(); }
    } trigger_guard{machine.camera.get()};
    // The head runs the sweep on its own thread; a cancel reaches it between lines.
    std::atomic<bool> head_abort{false};
    Status head_status;
    hw::ListControl control;
    control.abort = &head_abort;
    control.progress = [&](double) {
      if (cancel && cancel->load()) head_abort.store(true);
    };
    // Set by the head's thread once the sweep has ended on its own (done or failed, before
    // this thread aborted it). A sweep that fails wakes a camera waiting for its next pulse.
    std::atomic<bool> head_ended_itself{false};
    std::thread head([&] {
      head_status = machine.scanner->RunTriggeredSweep(sweep, control);
      if (!head_abort.load()) head_ended_itself.store(true);
      if (!head_status.ok()) machine.camera->WakeTriggered();
    });
    // Stops the head and says what it failed of itself: OK when it was fine, or when it was
    // only this thread's abort that stopped it (a camera fault is then the camera's to tell).
    const auto end_head = [&]() -> Status {
      head_abort.store(true);
      if (head.joinable()) head.join();
      return head_ended_itself.load() ? head_status : Status::Ok();
    };
    for (int i = 0; i < lines; ++i) {
      if (cancel && cancel->load()) {
        (void)end_head();
        return stop(Status(StatusCode::kCancelled, "scan cancelled"));
      }
      if (failed.load()) {
        (void)end_head();
        return stop(Status::Ok());
      }
      auto frame = machine.camera->Grab();
      if (!frame.ok()) {
        // The head's own failure explains a missing frame better than the camera's wait.
        const Status head_ended = end_head();
        if (cancel && cancel->load()) {
          return stop(Status(StatusCode::kCancelled, "scan cancelled"));
        }
        if (!head_ended.ok()) return stop(head_ended.Prefixed("scan head"));
        return stop(frame.status().Prefixed("line " + std::to_string(i) + ": camera"));
      }
      const Status taken = take(i, std::move(*frame));
      if (!taken.ok()) {
        (void)end_head();
        return stop(taken);
      }
      if (progress) progress(processed.load(), lines);
    }
    head.join();
    if (!head_status.ok()) return stop(head_status.Prefixed("scan head"));
  } else {
    // The pointer never keeps running after the scan, whatever happens.
    const PointerOff pointer_off{machine.scanner.get()};
    out.stats.trigger = "software";
    for (int i = 0; i < lines; ++i) {
      if (cancel && cancel->load()) return stop(Status(StatusCode::kCancelled, "scan cancelled"));
      if (failed.load()) return stop(Status::Ok());  // the processing thread's error
      const Status on =
          machine.scanner->StartPointerLine(line_from(i), line_to(i), sweep_speed);
      if (!on.ok()) return stop(on.Prefixed("line " + std::to_string(i)));
      machine.clock->SleepFor(options.settle_ms * 1e-3);
      auto frame = machine.camera->Grab();
      if (!frame.ok()) {
        return stop(frame.status().Prefixed("line " + std::to_string(i) + ": camera"));
      }
      const Status taken = take(i, std::move(*frame));
      if (!taken.ok()) return stop(taken);
      if (progress) progress(processed.load(), lines);
    }
  }
  out.stats.machine_time_s = machine.clock->Now() - t_start;
  INSITU_RETURN_IF_ERROR(join());
  out.stats.max_queued_frames = queue.max_size();
  if (progress) progress(lines, lines);
  // A scan that found the stripe in almost none of the columns its lines cover measured
  // nothing worth building on: say why here, not as a downstream symptom.
  out.stats.expected_columns =
      ExpectedColumns(options, Resolved(stripe_options, options, calibration), calibration);
  const ScanStats& st = out.stats;
  if (st.expected_columns > 0 &&
      static_cast<double>(st.valid) < options.min_stripe_fraction * st.expected_columns) {
    const std::string counts =
        "the scan found the stripe in " + std::to_string(st.valid) + " columns of about " +
        std::to_string(st.expected_columns) + " its lines cover (" +
        std::to_string(st.saturated) + " saturated, " + std::to_string(st.two_peaks) +
        " with two peaks; exposure " + std::to_string(st.exposure_ms) + " ms" +
        (options.auto_exposure ? ", by auto exposure" : "") +
        "; scan.min_stripe_fraction " + std::to_string(options.min_stripe_fraction) + ")";
    const std::string cure =
        st.saturated > st.valid
            ? (options.auto_exposure ? ": the stripe saturates the camera: lower camera.gain_db"
                                     : ": the stripe saturates the camera: lower "
                                       "camera.exposure_ms or set camera.auto_exposure: true")
            : (options.auto_exposure
                   ? ": too dark, or no part under the lines: check where the part lies (a part "
                     "much smaller than the lines: lower scan.min_stripe_fraction)"
                   : ": too dark, or no part under the lines: raise camera.exposure_ms, set "
                     "camera.auto_exposure: true, or check where the part lies");
    return DeviceError(counts + cure);
  }
  return out;
}

}  // namespace insitu::job
