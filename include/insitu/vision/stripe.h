// Laser-stripe centre extraction (seed 000 section 2.3, eq. 7).
//
// In: one camera frame (ImageView, 8- or 12-bit) showing a laser stripe.
// Out: for every scan line across the stripe (every column when the stripe runs roughly
// left-right, every row when it runs roughly top-bottom) the sub-pixel stripe centre, in pixel
// coordinates of the same image, or the reason there is none.
//
// Method, per scan line: 3x3 median filter (only where the stripe is, see the .cc), the maximum
// gray value gmax of the filtered profile, threshold K = k * gmax (0 < k < 1), the contiguous run
// of filtered pixels above K around the maximum, and the gray centroid of that run
// U = sum(g_i * u_i) / sum(g_i) (eq. 7). No centre is invented: a scan line with no stripe, a
// saturated stripe or two separate stripes is reported as such.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/colour.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

enum class StripeDirection {
  kAuto,     // decide from the image (principal axis of the bright pixels)
  kColumns,  // stripe runs left-right: one centre per column, centre is a row coordinate v
  kRows,     // stripe runs top-bottom: one centre per row, centre is a column coordinate u
};

enum class StripeStatus : uint8_t {
  kValid = 0,
  kNone,        // no stripe: filtered peak below min_peak or contrast below min_contrast
  kSaturated,   // the stripe reaches the sensor's full scale; its centroid is not trusted
  kTwoPeaks,    // a second, separate, stripe-like run above K in the scan line (reflection)
  kTooWide,     // the run above K is wider than max_width_px (blur, glare, not a stripe)
};

const char* StripeStatusName(StripeStatus status);

struct StripeOptions {
  StripeDirection direction = StripeDirection::kAuto;
  // k of K = k * gmax (seed 000 eq. 7).
  double threshold_ratio = 0.5;
  // Side of the square median filter, 1 (off) or 3.
  int median_kernel = 3;
  // A scan line whose filtered maximum is below this many gray levels (in the image's own
  // scale, 8- or 12-bit) holds no stripe.
  double min_peak = 20.0;
  // ... or whose maximum exceeds the scan line's background (median of the profile) by less.
  double min_contrast = 12.0;
  // A run above K wider than this is not a stripe.
  int max_width_px = 40;
  // Runs above K separated by at least this many pixels below K count as two peaks...
  int min_peak_separation_px = 3;
  // ... when the other run is at most max_width_px long (longer: a lit surface, not a stripe)
  // and peaks at this fraction of gmax or more (weaker: ambient light on a bright part beside a
  // weak stripe on a dark surface; the brighter run is the stripe). 0 counts every other run.
  double second_peak_ratio = 0.8;
  // Raw pixel value counted as saturated; 0 means the image's full scale.
  int saturation_level = 0;
  // Weight of pixel i in the centroid: gray value g_i (seed eq. 7) or g_i - K.
  bool subtract_threshold = false;
  // A colour camera's frames are read in this channel (ReduceToStripePlane): the pointer's.
  ColourChannel colour_channel = ColourChannel::kRed;

  // Names the first invalid field ("threshold_ratio must be in (0, 1), got 1.5").
  // These options with their gray levels (min_peak, min_contrast) given on the 8-bit scale,
  // for an image of `bit_depth` bits: scaled by (2^bits - 1) / 255, so a setting means the same
  // light on an 8- and a 12-bit camera (a 12-bit frame's noise alone exceeds 20 raw levels).
  StripeOptions ForBitDepth(int bit_depth) const;
  Status Validate() const;
};

struct StripeResult {
  StripeDirection direction = StripeDirection::kColumns;  // never kAuto
  // One entry per scan line (width entries for kColumns, height for kRows).
  std::vector<float> center;        // sub-pixel centre along the scan line; NaN if not valid
  std::vector<StripeStatus> status;
  std::vector<uint16_t> peak;       // filtered gmax of the scan line
  // Valid scan lines: the filtered level 3 pixels beyond the run's ends (the lower side), the
  // local background (ambient light on the surface) under the stripe; peak - base is the
  // stripe's own signal. 0 elsewhere.
  std::vector<uint16_t> base;
  std::vector<uint8_t> width_px;    // length of the run above K

  int valid_count() const;
  // Pixel coordinates (u, v) of scan line i's centre (only meaningful when valid).
  double u(int i) const { return direction == StripeDirection::kColumns ? i : center[i]; }
  double v(int i) const { return direction == StripeDirection::kColumns ? center[i] : i; }
};

// Reusable extractor: keeps its scratch buffers between frames (no allocation per frame once
// warmed up). Not thread-safe; use one per thread.
class StripeExtractor {
 public:
  explicit StripeExtractor(const StripeOptions& options);
  ~StripeExtractor();
  StripeExtractor(const StripeExtractor&) = delete;
  StripeExtractor& operator=(const StripeExtractor&) = delete;

  // Errors: invalid_argument for an empty image or an unsupported bit depth.
  Status Extract(const ImageView& image, StripeResult* result);

  const StripeOptions& options() const { return options_; }

 private:
  struct Scratch;
  StripeOptions options_;
  std::unique_ptr<Scratch> scratch_;
};

// The plane the extractor reads: a mono view as it is, a colour one reduced to `channel` in
// `scratch` (ReduceToChannel), which the returned view then shows. Errors: ReduceToChannel's.
Result<ImageView> StripePlane(const ImageView& image, ColourChannel channel, Image* scratch);

// Direction used by kAuto: principal axis of the pixels above half the image maximum, on a
// subsampled copy. Returns kColumns when no bright pixel exists.
StripeDirection EstimateStripeDirection(const ImageView& image);

}  // namespace insitu::vision
