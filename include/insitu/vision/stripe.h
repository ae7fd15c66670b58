// Laser-stripe centre extraction (seed 000 section 2.3, eq. 7).
//
// In: one camera frame (ImageView, 8- or 12-bit) showing a laser stripe.
// Out: for every scan line across the stripe (every column when the stripe runs roughly
// left-right, every row when it runs roughly top-bottom) the sub-pixel stripe centre, in pixel
// coordinates of the same image, or the reason there is none.
//
// Method, per scan line (seed 000 eq. 7, made to hold on real images):
//  * filtering: a 3x3 median (only where a stripe may be, see the .cc);
//  * the candidate: the stripe is a ridge, brighter than the profile on both sides of it; a lit
//    surface, a white label or the edge between two surfaces is not. The scan line's candidate
//    is its highest ridge (the brightest pixel only where there is none), at the local maximum
//    of the filtered profile g;
//  * the local background: two windows beside the run above K, as long as the run and half a
//    run away, joined by a straight line b(v); the peak's height above it is the contrast A;
//  * threshold K(v) = b(v) + k A (0 < k < 1), the contiguous run above K around the peak: where
//    the stripe is (the run's centroid of g_i - K_i) and its width at K;
//  * the centre: U = sum(w_i v_i) / sum(w_i) over the pixels within 3 beam sigmas of the run's
//    centroid (sigma from the width at K; the window's edge pixels by their share), w_i = g_i -
//    b'_i, b' the background line through the lowest pixel just outside the window on either
//    side: the stripe's own light over its whole profile, so room light on the surface, a
//    pedestal or a slope under the stripe does not pull it, and speckle on its flanks or peak
//    moves it less than a centroid cut at K (0.08 against 0.14 px rms on a matte part). Where
//    b' steps across the window by more than a tenth of A (an edge of the room's light), the
//    run's centroid;
//  * shape: the background may not step under the stripe by more than A, the centroid must lie
//    mid-way between the run's crossings of K (a symmetric beam), and the width at K may not
//    exceed 1.75 times the frame's stripe width (its median over the valid scan lines, or
//    expected_width_px) plus 1.5 px;
//  * one stripe only: any other run of the scan line that passes the same tests is a second
//    stripe (a reflection, or the line on two surfaces): two_peaks, whatever its brightness
//    (second_peak_ratio > 0 keeps the stronger when the other is that much weaker).
// No centre is invented: a scan line with no stripe, a saturated stripe, two stripes or a peak of
// the wrong shape is reported as such. Each valid centre carries its 1-sigma from the local
// noise.
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
  kNone,       // no stripe: filtered peak below min_peak or contrast below min_contrast
  kSaturated,  // the stripe reaches the sensor's full scale; its centroid is not trusted
  kTwoPeaks,   // a second, separate, stripe-like run above K in the scan line (reflection)
  kTooWide,    // the run above K is wider than max_width_px (blur, glare, not a stripe)
  kBadShape,   // a peak, but not a stripe's: lopsided, too wide for the frame's stripe, or on
               // a step of the background (a surface edge under it)
};

const char* StripeStatusName(StripeStatus status);

struct StripeOptions {
  StripeDirection direction = StripeDirection::kAuto;
  // k of K = b + k (gmax - b), b the local background under the peak (seed 000 eq. 7's
  // threshold, above the background).
  double threshold_ratio = 0.5;
  // Side of the square median filter, 1 (off) or 3.
  int median_kernel = 3;
  // A scan line whose filtered maximum is below this many gray levels (in the image's own
  // scale, 8- or 12-bit) holds no stripe.
  double min_peak = 20.0;
  // ... or whose peak stands less than this above its local background (the darker side, then
  // the windows beside the run).
  double min_contrast = 12.0;
  // A run above K wider than this is not a stripe (too_wide).
  int max_width_px = 40;
  // Dips below K shorter than this many pixels are noise inside one stripe and are bridged.
  int min_peak_separation_px = 3;
  // Another stripe-shaped peak in the scan line makes it two_peaks when its contrast is at least
  // this fraction of the stronger one's; 0 (default): whatever its brightness (a reflection of
  // the line is the same light, and its fraction says nothing about which is the surface).
  double second_peak_ratio = 0.0;
  // The stripe's width at K in pixels, for the shape test; 0: the median of the frame's valid
  // scan lines (at least 16 of them, else no width test).
  double expected_width_px = 0.0;
  // Raw pixel value counted as saturated; 0 means the image's full scale.
  int saturation_level = 0;
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
  // Valid scan lines: the local background (room light on the surface) under the peak; peak -
  // base is the stripe's own signal. 0 elsewhere.
  std::vector<uint16_t> base;
  std::vector<uint8_t> width_px;    // length of the run above K
  // Valid scan lines: the centre's standard uncertainty (pixels) from the noise of the local
  // background windows (the centroid's error propagation); NaN elsewhere. The scan's confidence
  // in the point.
  std::vector<float> sigma_px;

  int valid_count() const;
  // Pixel coordinates (u, v) of scan line i's centre (only meaningful when valid).
  double u(int i) const { return direction == StripeDirection::kColumns ? i : center[i]; }
  double v(int i) const { return direction == StripeDirection::kColumns ? center[i] : i; }
};

// Where the stripe may lie on each scan line: lo[i]..hi[i] along scan line i (rows of column i
// for kColumns, columns of row i for kRows), in the image's pixels; NaN in either: anywhere.
// The scan knows it from the light plane and the height range of its parts: a reflection or a
// lit surface outside it is never taken for the stripe.
struct StripeWindow {
  std::vector<float> lo, hi;
};

// Reusable extractor: keeps its scratch buffers between frames (no allocation per frame once
// warmed up). Not thread-safe; use one per thread.
class StripeExtractor {
 public:
  explicit StripeExtractor(const StripeOptions& options);
  ~StripeExtractor();
  StripeExtractor(const StripeExtractor&) = delete;
  StripeExtractor& operator=(const StripeExtractor&) = delete;

  // Errors: invalid_argument for an empty image or an unsupported bit depth, or a window
  // whose size is not the number of scan lines or with the direction left to kAuto.
  Status Extract(const ImageView& image, StripeResult* result,
                 const StripeWindow* window = nullptr);

  const StripeOptions& options() const { return options_; }

 private:
  struct Scratch;
  StripeOptions options_;
  std::unique_ptr<Scratch> scratch_;
};

// The plane the extractor reads: a mono view as it is, a colour one reduced to `channel` in
// `scratch` (ReduceToChannel), which the returned view then shows. Errors: ReduceToChannel's.
Result<ImageView> StripePlane(const ImageView& image, ColourChannel channel, Image* scratch);

// Direction used by kAuto: principal axis of the ridge pixels (brighter than the image 8 px
// away on both sides, across or along), on a subsampled copy: a lit face or a white board has
// none. Returns kColumns when there is no ridge. Image statistics only: a scan takes the
// direction from its calibration instead.
StripeDirection EstimateStripeDirection(const ImageView& image);

}  // namespace insitu::vision
