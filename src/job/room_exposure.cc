#include "job/room_exposure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "insitu/core/frame.h"
#include "insitu/vision/image.h"

namespace insitu::job {
namespace {

constexpr double kTarget = 0.65;         // the white squares' level, of full scale
constexpr double kTolerance = 0.15;      // relative: settled within it
constexpr double kMaxClipped = 0.005;    // of the board's pixels at full scale
constexpr int kMaxShots = 8;
constexpr double kInView = 0.25;         // a frame this bright (95th percentile) would show it

struct Level {
  bool found = false;
  double white = 0.0;     // gray levels
  double clipped = 0.0;   // fraction of the board's (or, not found, the frame's) pixels
};

// The q-quantile of the samples in the corners' bounding box (the whole frame: none).
Level Measure(const Frame& frame, const vision::ChessboardOptions& board) {
  Level out;
  const vision::ImageView view = vision::ViewOf(frame);
  int u0 = 0, v0 = 0, u1 = frame.width - 1, v1 = frame.height - 1;
  auto corners = vision::FindChessboard(view, board);
  if (corners.ok() && !corners->empty()) {
    out.found = true;
    double lo_u = 1e30, lo_v = 1e30, hi_u = -1e30, hi_v = -1e30;
    for (const Eigen::Vector2d& c : *corners) {
      lo_u = std::min(lo_u, c.x());
      hi_u = std::max(hi_u, c.x());
      lo_v = std::min(lo_v, c.y());
      hi_v = std::max(hi_v, c.y());
    }
    u0 = std::clamp(static_cast<int>(std::ceil(lo_u)), 0, frame.width - 1);
    u1 = std::clamp(static_cast<int>(std::floor(hi_u)), 0, frame.width - 1);
    v0 = std::clamp(static_cast<int>(std::ceil(lo_v)), 0, frame.height - 1);
    v1 = std::clamp(static_cast<int>(std::floor(hi_v)), 0, frame.height - 1);
  }
  std::vector<int> samples;
  samples.reserve(static_cast<size_t>(u1 - u0 + 1) * (v1 - v0 + 1));
  int clipped = 0;
  const int full = frame.max_value();
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) {
      const int g = frame.at(u, v);
      samples.push_back(g);
      clipped += g >= full;
    }
  }
  if (samples.empty()) return out;
  out.clipped = static_cast<double>(clipped) / samples.size();
  // Inside the corners about half the pixels are white squares: their level is the upper
  // tail, the 95th percentile (above the edges' blur, below a speck).
  const size_t k = static_cast<size_t>(0.95 * (samples.size() - 1));
  std::nth_element(samples.begin(), samples.begin() + k, samples.end());
  out.white = samples[k];
  return out;
}

std::string Ms(double ms) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g ms", ms);
  return text;
}

}  // namespace

Result<RoomExposure> ExposeForBoard(hw::Camera& camera, double start_ms, double min_ms,
                                    double max_ms, const vision::ChessboardOptions& board,
                                    const std::atomic<bool>* cancel) {
  RoomExposure out;
  double ms = std::clamp(start_ms, min_ms, max_ms);
  double measured_ms = -1.0;  // the last exposure the board was measured at, unclipped
  double measured_white = 0.0;
  double too_dark = 0.0, too_bright = 0.0;  // bracket: not found dark / clipped (0: unknown)
  bool not_in_view = false;
  int lit_misses = 0;  // frames lit well enough, without the board
  for (int shot = 0; shot < kMaxShots; ++shot) {
    if (cancel && cancel->load()) return Status(StatusCode::kCancelled, "cancelled");
    const Status set = camera.SetExposure(ms * 1e3);
    if (set.code() == StatusCode::kOutOfRange && shot > 0) break;  // at the camera's limit
    INSITU_RETURN_IF_ERROR(set.Prefixed("board exposure"));
    auto frame = camera.Grab();
    if (!frame.ok()) return frame.status().Prefixed("board exposure: camera");
    ++out.shots;
    const Level level = Measure(*frame, board);
    const double full = frame->max_value();
    double next = ms;
    const bool clipped = level.clipped > kMaxClipped || (level.found && level.white >= full);
    if (clipped) {
      too_bright = too_bright > 0 ? std::min(too_bright, ms) : ms;
      next = too_dark > 0 ? std::sqrt(too_dark * too_bright) : ms / 3.0;
    } else if (!level.found) {
      // Not found in a frame lit well enough to show it (its bright tail at a quarter of full
      // scale or more) and never seen clipped: a board turned away from the light may show at
      // three times the exposure; not found there either, it is not in view, and longer
      // exposures would only take longer.
      if (too_bright == 0.0 && level.white >= kInView * full && lit_misses++ > 0) {
        not_in_view = true;
        break;
      }
      too_dark = std::max(too_dark, ms);
      next = too_bright > 0 ? std::sqrt(too_dark * too_bright) : ms * 3.0;
    } else {
      measured_ms = ms;
      measured_white = level.white / full;
      if (std::abs(measured_white / kTarget - 1.0) <= kTolerance) {
        out.exposure_ms = ms;
        out.white_fraction = measured_white;
        return out;
      }
      next = ms * kTarget / std::max(measured_white, 1e-3);
    }
    next = std::clamp(next, min_ms, max_ms);
    if (next == ms) break;  // at the end of the range
    ms = next;
  }
  if (measured_ms > 0) {
    out.exposure_ms = measured_ms;
    out.white_fraction = measured_white;
    out.note = "board exposure did not settle in " + std::to_string(out.shots) +
               " frames: kept " + Ms(measured_ms) + " (white squares at " +
               std::to_string(static_cast<int>(std::lround(100 * measured_white))) +
               " % of full scale)";
  } else {
    out.exposure_ms = start_ms;
    out.note = "board exposure: the board was not seen unclipped in " +
               std::to_string(out.shots) + " frames from " + Ms(start_ms) + ": kept " +
               Ms(start_ms) + (not_in_view ? " (the frame is lit: is the board in view?)" : "");
  }
  INSITU_RETURN_IF_ERROR(camera.SetExposure(out.exposure_ms * 1e3).Prefixed("board exposure"));
  return out;
}

}  // namespace insitu::job
