// Tests of the stripe-centre extractor (seed 000 section 2.3, eq. 7).
//
// Images are synthetic: a Gaussian stripe profile integrated over each pixel (differences of
// erf), a constant background and seeded Gaussian noise. Two kinds of checks:
//  * against the truth: the centre error is bounded by the known truncation bias of eq. (7)
//    (computed below from the noise-free profile, sweeping the sub-pixel offset) plus a small
//    multiple of the centroid's noise (derived below);
//  * against a naive reference that applies the method literally (full-frame 3x3 median by
//    sorting, then per scan line gmax, K, run, centroid): the fast extractor must agree exactly,
//    which exercises its bands, block bounds and retries on curved, steep, wide and double
//    stripes and on hot pixels.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "insitu/vision/image.h"
#include "insitu/vision/stripe.h"

namespace insitu::vision {
namespace {

// ---------------------------------------------------------------------------------------------
// Synthetic images.

// Mean over the pixel [d - 0.5, d + 0.5] of exp(-x^2 / (2 sigma^2)), times `amplitude`.
double PixelGaussian(double d, double sigma, double amplitude) {
  const double w = std::sqrt(2.0) * sigma;
  return amplitude * sigma * std::sqrt(M_PI / 2.0) *
         (std::erf((d + 0.5) / w) - std::erf((d - 0.5) / w));
}

// Gray values as doubles while rendering; View() quantizes into an 8- or 16-bit buffer with a
// padded stride (so stride handling is exercised).
struct TestImage {
  int width = 0;
  int height = 0;
  int bit_depth = 8;
  std::vector<double> value;
  std::vector<uint8_t> bytes;

  TestImage(int w, int h, int depth, double background)
      : width(w), height(h), bit_depth(depth), value(static_cast<size_t>(w) * h, background) {}

  double& at(int u, int v) { return value[static_cast<size_t>(v) * width + u]; }
  double at(int u, int v) const { return value[static_cast<size_t>(v) * width + u]; }
  int max_value() const { return (1 << bit_depth) - 1; }

  // Stripe running left-right: centre row center(u) in column u, for u in [u0, u1).
  void AddRowStripe(const std::function<double(int)>& center, double sigma, double amplitude,
                    int u0 = 0, int u1 = -1) {
    if (u1 < 0) u1 = width;
    for (int u = u0; u < u1; ++u) {
      const double c = center(u);
      for (int v = 0; v < height; ++v) at(u, v) += PixelGaussian(v - c, sigma, amplitude);
    }
  }
  // Stripe running top-bottom: centre column center(v) in row v.
  void AddColumnStripe(const std::function<double(int)>& center, double sigma, double amplitude) {
    for (int v = 0; v < height; ++v) {
      const double c = center(v);
      for (int u = 0; u < width; ++u) at(u, v) += PixelGaussian(u - c, sigma, amplitude);
    }
  }
  // Straight line through (cu, cv) at `angle_deg` from the u axis (for the direction estimate).
  void AddLine(double cu, double cv, double angle_deg, double sigma, double amplitude) {
    const double a = angle_deg * M_PI / 180.0;
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const double d = -(u - cu) * std::sin(a) + (v - cv) * std::cos(a);
        at(u, v) += amplitude * std::exp(-d * d / (2 * sigma * sigma));
      }
    }
  }
  void AddNoise(double sigma, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> gauss(0.0, sigma);
    for (double& x : value) x += gauss(rng);
  }

  int Quantized(int u, int v) const {
    return static_cast<int>(std::clamp(std::round(at(u, v)), 0.0, double(max_value())));
  }

  ImageView View(int pad_pixels = 3) {
    const size_t bpp = bit_depth == 8 ? 1 : 2;
    const size_t stride = (width + pad_pixels) * bpp;
    bytes.assign(stride * height, 0xAB);  // padding holds garbage on purpose
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const int q = Quantized(u, v);
        if (bpp == 1) {
          bytes[v * stride + u] = static_cast<uint8_t>(q);
        } else {
          const uint16_t s = static_cast<uint16_t>(q);
          std::memcpy(&bytes[v * stride + 2 * u], &s, 2);
        }
      }
    }
    ImageView view;
    view.data = bytes.data();
    view.width = width;
    view.height = height;
    view.stride_bytes = stride;
    view.bit_depth = bit_depth;
    return view;
  }

  TestImage Transposed() const {
    TestImage t(height, width, bit_depth, 0.0);
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) t.at(v, u) = at(u, v);
    }
    return t;
  }
};

StripeOptions ColumnOptions() {
  StripeOptions o;
  o.direction = StripeDirection::kColumns;
  return o;
}

StripeResult ExtractOrFail(const StripeOptions& options, const ImageView& view) {
  StripeExtractor extractor(options);
  StripeResult result;
  const Status st = extractor.Extract(view, &result);
  EXPECT_TRUE(st.ok()) << st.ToString();
  return result;
}

// ---------------------------------------------------------------------------------------------
// The naive reference: the method of stripe.h applied literally, column by column, on the whole
// filtered column: every local maximum of it is a candidate, evaluated as stripe.h says.

// One candidate, as the method evaluates it (the same steps as the extractor's, written out on
// a plain profile: integers from an image, or doubles for the noise-free error model).
struct RefCandidate {
  StripeStatus status = StripeStatus::kNone;
  int rp = 0;
  double gmax = 0;
  int rs = 0, re = -1;
  double base = 0, contrast = 0, center = NAN, width = 0;
  double run_center = NAN;    // the run's centroid of g - K (the window's centre)
  int len = 0;                // the background windows' length (WindowCentroid)
  std::vector<double> level;  // K_i over the run (for the error model)
  double noise = 0;           // the windows' scatter
};

// The centre over the whole profile: the centroid of g - b in the window of +-3 beam sigmas
// about the run's centroid c0, sigma from the width at K (a Gaussian's width at k of its peak is
// 2 sigma sqrt(2 ln(1/k))), every pixel weighted by its share of [r - 0.5, r + 0.5] inside the
// window, the window cut symmetrically at the profile's ends. b: the line through the lowest of
// the `len` pixels just outside the window on either side (one side's when the profile ends
// there; `fallback` at the run's ends rs, re when both do). sum: the sum of the weights;
// noise_gain: sqrt(sum share^2 (r - c0)^2) / sum, the centre's noise per unit of a pixel's own
// noise.
struct WindowCentre {
  double center = NAN;
  double sum = 0;
  double noise_gain = 0;
  double step = 0;  // |b's two points' difference|: the background's step across the window
  double m2 = 0;    // sum share (r - c0)^2: the centre's lever on b's slope
  double span = 0;  // rows between b's two points
};
template <typename G, typename B>
WindowCentre WindowCentroid(const std::vector<G>& g, double c0, double width, double k, int len,
                            int rs, int re, const B& fallback) {
  const int n = static_cast<int>(g.size());
  const double sigma = width / (2.0 * std::sqrt(2.0 * std::log(1.0 / k)));
  const double half = std::min({3.0 * sigma, c0 + 0.5, n - 0.5 - c0});
  // The lowest pixel (the first of equals from the window's start) of the `len` pixels just
  // outside the window on either side.
  double b[2] = {INFINITY, INFINITY}, m[2] = {0, 0};
  const int last_before = static_cast<int>(std::floor(c0 - half - 0.5));
  const int first_after = static_cast<int>(std::ceil(c0 + half + 0.5));
  for (int r = last_before - len + 1; r <= last_before; ++r) {
    if (r >= 0 && r < n && g[r] < b[0]) b[0] = g[r], m[0] = r;
  }
  for (int r = first_after; r < first_after + len; ++r) {
    if (r >= 0 && r < n && g[r] < b[1]) b[1] = g[r], m[1] = r;
  }
  for (int s = 0; s < 2; ++s) {
    const int o = 1 - s;
    if (std::isfinite(b[s])) continue;
    if (std::isfinite(b[o])) {
      b[s] = b[o], m[s] = m[o] + (s == 0 ? -1 : 1);
    } else {
      b[s] = fallback(s == 0 ? rs : re), m[s] = s == 0 ? rs : re;
    }
  }
  auto bg = [&](double r) { return b[0] + (b[1] - b[0]) * (r - m[0]) / (m[1] - m[0]); };
  double s0 = 0, s1 = 0, spread = 0;
  for (int r = 0; r < n; ++r) {
    const double lo = std::max(r - 0.5, c0 - half), hi = std::min(r + 0.5, c0 + half);
    if (hi <= lo) continue;
    const double share = hi - lo;
    s0 += share * (g[r] - bg(r));
    s1 += share * (g[r] - bg(r)) * (r - c0);
    spread += share * share * (r - c0) * (r - c0);
  }
  WindowCentre w;
  w.sum = s0;
  w.step = std::abs(b[1] - b[0]);
  w.span = m[1] - m[0];
  for (int r = 0; r < n; ++r) {
    const double lo = std::max(r - 0.5, c0 - half), hi = std::min(r + 0.5, c0 + half);
    if (hi > lo) w.m2 += (hi - lo) * (r - c0) * (r - c0);
  }
  if (s0 > 0) {
    w.center = c0 + s1 / s0;
    w.noise_gain = std::sqrt(spread) / s0;
  }
  return w;
}

template <typename G>
RefCandidate RefEvaluate(const std::vector<G>& g, const std::vector<int>* raw, int seed,
                         const StripeOptions& o, double column_background, int saturation) {
  const int n = static_cast<int>(g.size());
  RefCandidate c;
  int rp = seed;
  while (rp + 1 < n && g[rp + 1] > g[rp]) ++rp;
  while (rp > 0 && g[rp - 1] >= g[rp]) --rp;
  c.rp = rp;
  c.gmax = g[rp];
  if (c.gmax < o.min_peak) return c;
  const int reach = std::clamp(o.max_width_px / 4, 4, 16);
  double darker = INFINITY;
  if (rp - reach >= 0) darker = g[rp - reach];
  if (rp + reach < n) darker = std::min<double>(darker, g[rp + reach]);
  if (!std::isfinite(darker)) darker = column_background;
  c.contrast = c.gmax - darker;
  if (c.contrast < o.min_contrast) return c;
  // The valleys: walk out while the profile falls (a rise of min_contrast / 2 or reach rows
  // without a new minimum end it), at most max_width_px rows.
  double b0 = INFINITY;
  for (int dir : {-1, 1}) {
    double low = c.gmax;
    int low_row = rp, last = rp;
    for (int r = rp + dir; r >= 0 && r < n && std::abs(r - rp) <= o.max_width_px; r += dir) {
      last = r;
      if (g[r] < low) {
        low = g[r];
        low_row = r;
      } else if (g[r] > low + 0.5 * o.min_contrast || std::abs(r - low_row) >= reach) {
        break;
      }
    }
    if (last == rp) continue;
    b0 = std::min(b0, low);
  }
  if (!std::isfinite(b0)) b0 = darker;
  c.contrast = c.gmax - b0;
  if (c.contrast < o.min_contrast) return c;
  const double k = o.threshold_ratio;
  auto run_around = [&](const std::function<double(int)>& level, int* rs, int* re) {
    *re = rp;
    for (int r = rp + 1, gap = 0; r < n; ++r) {
      if (g[r] > level(r)) {
        *re = r;
        gap = 0;
        if (*re - rp >= o.max_width_px) break;
      } else if (++gap >= o.min_peak_separation_px) {
        break;
      }
    }
    *rs = rp;
    for (int r = rp - 1, gap = 0; r >= 0; --r) {
      if (g[r] > level(r)) {
        *rs = r;
        gap = 0;
        if (rp - *rs >= o.max_width_px) break;
      } else if (++gap >= o.min_peak_separation_px) {
        break;
      }
    }
  };
  auto saturated = [&](int a, int b) {
    if (raw == nullptr) return false;
    for (int r = a; r <= b; ++r) {
      if ((*raw)[r] >= saturation) return true;
    }
    return false;
  };
  const double level0 = b0 + k * c.contrast;
  run_around([&](int) { return level0; }, &c.rs, &c.re);
  if (saturated(c.rs, c.re)) return c.status = StripeStatus::kSaturated, c;
  if (c.re - c.rs + 1 > o.max_width_px) return c.status = StripeStatus::kTooWide, c;
  const int run = c.re - c.rs + 1;
  const int gap = std::max(2, run / 2), len = std::max(3, run);
  std::vector<double> side[2];
  double mid[2] = {0, 0};
  for (int s = 0; s < 2; ++s) {
    const int from = s == 0 ? c.rs - gap - len + 1 : c.re + gap;
    for (int r = from; r < from + len; ++r) {
      if (r < 0 || r >= n) continue;
      side[s].push_back(g[r]);
      mid[s] += r;
    }
  }
  double mean[2] = {b0, b0}, ss = 0;
  int dof = 0;
  for (int s = 0; s < 2; ++s) {
    if (side[s].empty()) continue;
    mean[s] = 0;
    for (double x : side[s]) mean[s] += x;
    mean[s] /= side[s].size();
    mid[s] /= side[s].size();
    for (double x : side[s]) ss += (x - mean[s]) * (x - mean[s]);
    dof += static_cast<int>(side[s].size()) - 1;
  }
  if (side[0].empty()) mean[0] = mean[1], mid[0] = mid[1] - 1;
  if (side[1].empty()) mean[1] = mean[0], mid[1] = mid[0] + 1;
  c.noise = dof > 0 ? std::sqrt(ss / dof) : 0.0;
  auto bg = [&](double r) {
    return mean[0] + (mean[1] - mean[0]) * (r - mid[0]) / (mid[1] - mid[0]);
  };
  c.base = bg(rp);
  c.contrast = c.gmax - c.base;
  if (c.contrast < o.min_contrast) return c.status = StripeStatus::kNone, c;
  if (!side[0].empty() && !side[1].empty() && std::abs(mean[1] - mean[0]) > c.contrast) {
    return c.status = StripeStatus::kBadShape, c;
  }
  auto level = [&](int r) { return bg(r) + k * c.contrast; };
  run_around(level, &c.rs, &c.re);
  if (saturated(c.rs, c.re)) return c.status = StripeStatus::kSaturated, c;
  if (c.re - c.rs + 1 > o.max_width_px) return c.status = StripeStatus::kTooWide, c;
  double s0 = 0, s1 = 0;
  for (int r = c.rs; r <= c.re; ++r) {
    c.level.push_back(level(r));
    const double w = std::max(g[r] - level(r), 0.0);
    s0 += w;
    s1 += w * r;
  }
  if (!(s0 > 0)) return c.status = StripeStatus::kNone, c;
  c.run_center = s1 / s0;
  auto crossing = [&](int in, int out) {
    if (out < 0 || out >= n) return in + 0.5 * (out - in);
    const double gi = g[in], go = g[out], kl = level(in);
    const double t = gi > go ? std::clamp((gi - kl) / (gi - go), 0.0, 1.0) : 0.5;
    return in + t * (out - in);
  };
  const double x0 = crossing(c.rs, c.rs - 1), x1 = crossing(c.re, c.re + 1);
  c.width = x1 - x0;
  if (c.width < 1.1) return c.status = StripeStatus::kBadShape, c;  // one pixel wide
  if (std::abs(c.run_center - 0.5 * (x0 + x1)) > 0.15 * c.width + 0.35) {
    return c.status = StripeStatus::kBadShape, c;
  }
  c.len = len;
  const WindowCentre w = WindowCentroid(g, c.run_center, c.width, k, len, c.rs, c.re, bg);
  // A background stepping by more than a tenth of the contrast, or no light above it: the
  // run's centroid.
  c.center = w.step > 0.1 * c.contrast || !(w.sum > 0) ? c.run_center : w.center;
  c.status = StripeStatus::kValid;
  return c;
}

struct RefLine {
  StripeStatus status = StripeStatus::kNone;
  double center = NAN;
  int peak = 0;
  int width = 0;
  double width_k = NAN;
  bool ambiguous = false;  // a candidate within the noise of a decision
  std::string candidates;  // the valid candidates (row: contrast), for a failure's message
  double evidence = NAN;   // where the column sees the stripe: valid centre, or clipped peak
};

std::vector<int> NaiveMedian3x3(const TestImage& img, int kernel) {
  std::vector<int> out(static_cast<size_t>(img.width) * img.height);
  for (int v = 0; v < img.height; ++v) {
    for (int u = 0; u < img.width; ++u) {
      if (kernel == 1) {
        out[v * img.width + u] = img.Quantized(u, v);
        continue;
      }
      std::array<int, 9> w;
      int i = 0;
      for (int dv = -1; dv <= 1; ++dv) {
        for (int du = -1; du <= 1; ++du) {
          w[i++] = img.Quantized(std::clamp(u + du, 0, img.width - 1),
                                 std::clamp(v + dv, 0, img.height - 1));
        }
      }
      std::nth_element(w.begin(), w.begin() + 4, w.end());
      out[v * img.width + u] = w[4];
    }
  }
  return out;
}

// Every local maximum of the column (the first row of a flat top) is a candidate; one valid is
// the stripe, two (the weaker at least second_peak_ratio of the stronger) are two peaks, and a
// saturated one beside a valid one too. A
// candidate whose contrast lies within `tolerance` of min_contrast makes the column ambiguous:
// the extractor looks for candidates at ridges of its block maxima (see stripe.cc), which may
// not reach a candidate that weak.
RefLine RefColumn(const std::vector<int>& g, const std::vector<int>& raw, const StripeOptions& o,
                  int saturation, double tolerance) {
  const int n = static_cast<int>(g.size());
  std::vector<int> sorted = raw;
  std::nth_element(sorted.begin(), sorted.begin() + (n - 1) / 2, sorted.end());
  const double background = sorted[(n - 1) / 2];
  RefLine out;
  out.peak = *std::max_element(g.begin(), g.end());
  std::vector<RefCandidate> valid;
  std::vector<int> seen;
  bool clipped = false;  // a saturated peak: maybe the stripe
  // Highest first: a peak within min_peak_separation_px of a valid candidate's run and no
  // higher is part of that stripe, not a candidate.
  std::vector<int> peaks;
  for (int r = 0; r < n; ++r) {
    if ((r > 0 && g[r - 1] >= g[r]) || (r + 1 < n && g[r + 1] > g[r])) continue;
    peaks.push_back(r);
  }
  std::stable_sort(peaks.begin(), peaks.end(), [&](int a, int b) { return g[a] > g[b]; });
  for (int r : peaks) {
    bool part = false;
    for (const RefCandidate& v : valid) {
      part = part || (r >= v.rs - o.min_peak_separation_px &&
                      r <= v.re + o.min_peak_separation_px && g[r] <= v.gmax);
    }
    if (part) continue;
    const RefCandidate c = RefEvaluate(g, &raw, r, o, background, saturation);
    if (std::abs(c.contrast - o.min_contrast) <= tolerance) out.ambiguous = true;
    if (c.status == StripeStatus::kSaturated && !clipped) out.evidence = 0.5 * (c.rs + c.re);
    clipped = clipped || c.status == StripeStatus::kSaturated;
    if (c.status != StripeStatus::kValid) continue;
    if (std::find(seen.begin(), seen.end(), c.rp) != seen.end()) continue;
    seen.push_back(c.rp);
    valid.push_back(c);
    out.candidates += " " + std::to_string(c.rp) + ": " + std::to_string(c.contrast);
  }
  if (valid.empty()) {
    if (clipped) out.status = StripeStatus::kSaturated;
    return out;
  }
  if (clipped) {
    out.status = StripeStatus::kTwoPeaks;
    out.evidence = NAN;
    return out;
  }
  // A peak much wider than the narrowest is not the beam; of the rest, the strongest, and any
  // other clear of its run at least second_peak_ratio of its contrast makes two peaks.
  double narrowest = INFINITY;
  for (const RefCandidate& c : valid) narrowest = std::min(narrowest, c.width);
  const double limit = 1.75 * narrowest + 1.5;
  std::vector<RefCandidate> kept;
  for (const RefCandidate& c : valid) {
    if (c.width <= limit) kept.push_back(c);
  }
  std::sort(kept.begin(), kept.end(),
            [](const RefCandidate& a, const RefCandidate& b) { return a.contrast > b.contrast; });
  for (size_t i = 1; i < kept.size(); ++i) {
    const bool overlaps = kept[i].rs <= kept[0].re + o.min_peak_separation_px &&
                          kept[i].re >= kept[0].rs - o.min_peak_separation_px;
    if (!overlaps && kept[i].contrast >= o.second_peak_ratio * kept[0].contrast) {
      out.status = StripeStatus::kTwoPeaks;
      return out;
    }
  }
  out.status = StripeStatus::kValid;
  out.center = out.evidence = kept[0].center;
  out.peak = static_cast<int>(kept[0].gmax);
  out.width = kept[0].re - kept[0].rs + 1;
  out.width_k = kept[0].width;
  return out;
}

// Reference result for every column of a kColumns image, with the frame's width test.
std::vector<RefLine> Reference(const TestImage& img, const StripeOptions& o, double tolerance = 0) {
  const std::vector<int> filtered = NaiveMedian3x3(img, o.median_kernel);
  const int saturation = o.saturation_level > 0 ? o.saturation_level : img.max_value();
  std::vector<RefLine> out;
  for (int u = 0; u < img.width; ++u) {
    std::vector<int> g(img.height), raw(img.height);
    for (int v = 0; v < img.height; ++v) {
      g[v] = filtered[v * img.width + u];
      raw[v] = img.Quantized(u, v);
    }
    out.push_back(RefColumn(g, raw, o, saturation, tolerance));
  }
  std::vector<double> widths;
  for (const RefLine& l : out) {
    if (l.status == StripeStatus::kValid) widths.push_back(l.width_k);
  }
  double expected = o.expected_width_px;
  if (!(expected > 0) && widths.size() >= 16) {
    std::nth_element(widths.begin(), widths.begin() + widths.size() / 2, widths.end());
    expected = widths[widths.size() / 2];
  }
  if (expected > 0) {
    for (RefLine& l : out) {
      if (l.status == StripeStatus::kValid && l.width_k > 1.75 * expected + 1.5) {
        l.status = StripeStatus::kBadShape;
      }
    }
  }
  for (RefLine& l : out) {
    if (l.status == StripeStatus::kBadShape) l.evidence = NAN;
  }
  // Continuity: a centre over 3 px from the agreeing medians of where up to 4 neighbours on
  // each side see the stripe (valid centres, clipped peaks; at least one) is isolated; until
  // nothing changes.
  const int n = static_cast<int>(out.size());
  auto side = [&](int u, int dir, double* med) {
    std::vector<double> v;
    for (int i = 1; i <= 4 && u + dir * i >= 0 && u + dir * i < n; ++i) {
      if (!std::isnan(out[u + dir * i].evidence)) v.push_back(out[u + dir * i].evidence);
    }
    if (v.empty()) return false;
    std::sort(v.begin(), v.end());
    *med = v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    return true;
  };
  for (int round = 0; round < 4; ++round) {
    std::vector<int> isolated;
    for (int u = 0; u < n; ++u) {
      double l = 0, r = 0;
      if (out[u].status != StripeStatus::kValid || !side(u, -1, &l) || !side(u, 1, &r)) continue;
      const double c = out[u].center;
      if (std::abs(l - r) <= 3 && std::abs(c - l) > 3 && std::abs(c - r) > 3) isolated.push_back(u);
    }
    if (isolated.empty()) break;
    for (int u : isolated) {
      out[u].status = StripeStatus::kBadShape;
      out[u].evidence = NAN;
    }
  }
  return out;
}

// Agreement with the reference on every column; returns the number of valid columns. Valid,
// two-peak and other columns must agree (the reason a column holds no stripe may differ: the
// reference evaluates every local maximum, the extractor its ridges); valid centres exactly.
// Columns the reference finds ambiguous (a candidate's contrast within `contrast_tolerance` of
// min_contrast) are skipped and counted in *skipped.
//
// With `missed` given, a peak the extractor never looked at is counted there instead of failing:
// it seeks other stripes at the ridges of its block maxima and near the ones it finds, and a
// ridge hides behind anything brighter 2 blocks (16 rows) to its side outside the band it
// filters (see stripe.cc). Such a column is valid where the reference finds two peaks (a
// second stripe missed), or not valid where the reference finds one (the stripe missed behind
// a saturated defect). Never the other way: a stripe the extractor reports is one.
int ExpectMatchesReference(TestImage& img, const StripeOptions& o, double contrast_tolerance = 0,
                           int* skipped = nullptr, int* missed = nullptr) {
  const StripeResult r = ExtractOrFail(o, img.View());
  const std::vector<RefLine> ref = Reference(img, o, contrast_tolerance);
  EXPECT_EQ(r.direction, StripeDirection::kColumns);
  EXPECT_EQ(r.status.size(), ref.size());
  auto kind = [](StripeStatus s) {
    return s == StripeStatus::kValid      ? "valid"
           : s == StripeStatus::kTwoPeaks ? "two_peaks"
                                          : "other";
  };
  int valid = 0;
  for (int u = 0; u < img.width && u < static_cast<int>(r.status.size()); ++u) {
    if (contrast_tolerance > 0 && ref[u].ambiguous) {
      if (skipped != nullptr) ++*skipped;
      continue;
    }
    const bool valid_here = r.status[u] == StripeStatus::kValid;
    const bool missed_second = valid_here && ref[u].status == StripeStatus::kTwoPeaks;
    const bool missed_stripe = !valid_here && r.status[u] != StripeStatus::kTwoPeaks &&
                               ref[u].status == StripeStatus::kValid;
    if (missed != nullptr && (missed_second || missed_stripe)) {
      ++*missed;
      continue;
    }
    // Status names print readably; the context helps to rebuild a failing random scene.
    EXPECT_STREQ(kind(r.status[u]), kind(ref[u].status))
        << "column " << u << " of " << img.width << "x" << img.height << ": "
        << StripeStatusName(r.status[u]) << " (reference " << StripeStatusName(ref[u].status)
        << "), peak " << r.peak[u] << " (reference " << ref[u].peak << "), run "
        << int{r.width_px[u]} << " (" << ref[u].width << "), k " << o.threshold_ratio
        << ", separation " << o.min_peak_separation_px << ", max width " << o.max_width_px
        << ", kernel " << o.median_kernel << "; reference candidates" << ref[u].candidates
        << "; centre " << r.center[u];
    if (ref[u].status != StripeStatus::kValid || !valid_here) continue;
    ++valid;
    EXPECT_EQ(r.peak[u], ref[u].peak) << "column " << u;
    EXPECT_NEAR(r.center[u], ref[u].center, 1e-4) << "column " << u;
    EXPECT_EQ(r.width_px[u], ref[u].width) << "column " << u;
  }
  return valid;
}

// ---------------------------------------------------------------------------------------------
// The error model of eq. (7) with the local background removed, from the noise-free profile.
//
// A stripe with centre c + slope * du in column u + du: the 3x3 median of the noise-free image at
// (u, v) is the median of the 9 values p(v + dv - c - slope * du), which for slope 0 is the
// vertical 3-median of the 1-D profile.

struct ErrorModel {
  double bias_bound = 0;   // max over the sub-pixel offset of |U - c| without noise
  double sigma_bound = 0;  // max over the offset of the centroid's noise std (see below)
};

// The noise-free filtered profile of a column whose stripe centre is c (rows 0..100).
std::vector<double> NoiseFreeProfile(double c, double slope, double sigma, double amplitude,
                                     double background) {
  const int n = 101;
  std::vector<double> g(n);
  for (int v = 0; v < n; ++v) {
    std::array<double, 9> w;
    int i = 0;
    for (int du = -1; du <= 1; ++du) {
      for (int dv = -1; dv <= 1; ++dv) {
        const int vv = std::clamp(v + dv, 0, n - 1);
        w[i++] = background + PixelGaussian(vv - c - slope * du, sigma, amplitude);
      }
    }
    std::nth_element(w.begin(), w.begin() + 4, w.end());
    g[v] = w[4];
  }
  return g;
}

// The least distance of the noise-free profile from K: noise below it keeps the run fixed.
double RunMargin(const std::vector<double>& g, const RefCandidate& line) {
  const double kc = line.level[line.rp - line.rs];
  double margin = INFINITY;
  for (double x : g) margin = std::min(margin, std::abs(x - kc));
  return margin;
}

RefCandidate NoiseFreeCentroid(const std::vector<double>& g, const StripeOptions& o) {
  const int rp = static_cast<int>(std::max_element(g.begin(), g.end()) - g.begin());
  return RefEvaluate(g, nullptr, rp, o, 0.0, 1 << 30);
}

// The centre is the window's centroid (WindowCentroid) about the run's centroid c0.
//
// Noise: U = c0 + sum(f_i w_i (v_i - c0)) / sum(f_i w_i), w_i = g_i - b_i, f_i the window's
// shares; with independent noise e_i of std n on g_i, dU/de_i = f_i (v_i - U) / sum(f w), so
// std(U) = n sqrt(sum f_i^2 (v_i - U)^2) / sum(f_i w_i) (the noise_gain), and the background's
// two points, each a pixel with noise n, tilt b by n sqrt(2) / span, which moves U by that
// times sum f_i (v_i - c0)^2 / sum(f w); the two in quadrature. c0 moves the window, which
// weighs the profile's tails only (second order). The 3x3 median reduces the per-pixel noise
// (to ~0.4 n on a flat patch) but correlates neighbouring rows; the raw n is used as a
// conservative value, plus 1/12 LSB^2 of quantization.
//
// Bias: the window's truncation of the tails (3 sigma out, its edges by share), and noise
// moving an end pixel of the run whose value lies close to K across it, which moves c0 and
// with it the window. The bound is the largest |U - c| over all offsets and over the runs with
// each end pixel within 5 noise sigmas of K toggled.
ErrorModel ComputeErrorModel(double sigma, double amplitude, double background, double noise,
                             const StripeOptions& o, double slope = 0.0) {
  ErrorModel m;
  const double n_eff = std::sqrt(noise * noise + 1.0 / 12.0);
  for (int step = 0; step < 200; ++step) {
    const double c = 50.0 + step / 200.0;
    const std::vector<double> g = NoiseFreeProfile(c, slope, sigma, amplitude, background);
    const RefCandidate base = NoiseFreeCentroid(g, o);
    if (base.status != StripeStatus::kValid) continue;
    const double kc = base.level[base.rp - base.rs];  // K at the peak (flat background)
    auto near_k = [&](int v) { return std::abs(g[v] - kc) < 5 * n_eff; };
    const auto flat = [&](double) { return background; };
    for (int ds = -1; ds <= 1; ++ds) {
      for (int de = -1; de <= 1; ++de) {
        int rs = base.rs + ds, re = base.re + de;
        if (ds != 0 && !near_k(ds < 0 ? base.rs - 1 : base.rs)) continue;
        if (de != 0 && !near_k(de > 0 ? base.re + 1 : base.re)) continue;
        if (rs > re) continue;
        double s0 = 0, s1 = 0;
        for (int v = rs; v <= re; ++v) {
          const double w = std::max(g[v] - kc, 0.0);
          s0 += w;
          s1 += w * v;
        }
        if (!(s0 > 0)) continue;
        const WindowCentre w =
            WindowCentroid(g, s1 / s0, base.width, o.threshold_ratio, base.len, rs, re, flat);
        if (!(w.sum > 0)) continue;
        const double tilt = n_eff * std::sqrt(2.0) / w.span * w.m2 / w.sum;
        m.bias_bound = std::max(m.bias_bound, std::abs(w.center - c));
        m.sigma_bound = std::max(m.sigma_bound, std::hypot(n_eff * w.noise_gain, tilt));
      }
    }
  }
  return m;
}

// ---------------------------------------------------------------------------------------------
// Options and errors.

TEST(StripeOptionsTest, DefaultsAreValid) {
  EXPECT_TRUE(StripeOptions{}.Validate().ok());
}

TEST(StripeOptionsTest, ValidateNamesTheBadField) {
  struct Case {
    std::function<void(StripeOptions&)> set;
    const char* field;
  };
  const std::vector<Case> cases = {
      {[](StripeOptions& o) { o.threshold_ratio = 1.5; }, "threshold_ratio"},
      {[](StripeOptions& o) { o.threshold_ratio = 0.0; }, "threshold_ratio"},
      {[](StripeOptions& o) { o.threshold_ratio = NAN; }, "threshold_ratio"},
      {[](StripeOptions& o) { o.median_kernel = 5; }, "median_kernel"},
      {[](StripeOptions& o) { o.min_peak = -1; }, "min_peak"},
      {[](StripeOptions& o) { o.min_contrast = INFINITY; }, "min_contrast"},
      {[](StripeOptions& o) { o.max_width_px = 0; }, "max_width_px"},
      {[](StripeOptions& o) { o.max_width_px = 256; }, "max_width_px"},
      {[](StripeOptions& o) { o.min_peak_separation_px = 0; }, "min_peak_separation_px"},
      {[](StripeOptions& o) { o.second_peak_ratio = 1.2; }, "second_peak_ratio"},
      {[](StripeOptions& o) { o.second_peak_ratio = NAN; }, "second_peak_ratio"},
      {[](StripeOptions& o) { o.saturation_level = -2; }, "saturation_level"},
      {[](StripeOptions& o) { o.direction = static_cast<StripeDirection>(7); }, "direction"},
  };
  for (const Case& c : cases) {
    StripeOptions o;
    c.set(o);
    const Status st = o.Validate();
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(st.message().find(c.field), std::string::npos) << st.message();
  }
  StripeOptions o;
  o.threshold_ratio = 1.5;
  EXPECT_NE(o.Validate().message().find("1.5"), std::string::npos) << o.Validate().message();
}

TEST(StripeExtractorTest, InvalidOptionsAreReportedByExtract) {
  StripeOptions o = ColumnOptions();
  o.median_kernel = 2;
  TestImage img(16, 16, 8, 10);
  StripeExtractor extractor(o);
  StripeResult result;
  const Status st = extractor.Extract(img.View(), &result);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("median_kernel"), std::string::npos) << st.message();
}

TEST(StripeExtractorTest, RejectsEmptyAndMalformedImages) {
  StripeExtractor extractor(ColumnOptions());
  StripeResult result;
  ImageView empty;
  EXPECT_EQ(extractor.Extract(empty, &result).code(), StatusCode::kInvalidArgument);
  EXPECT_NE(extractor.Extract(empty, &result).message().find("empty"), std::string::npos);

  TestImage img(8, 6, 8, 10);
  ImageView view = img.View();
  ImageView zero_width = view;
  zero_width.width = 0;
  EXPECT_EQ(extractor.Extract(zero_width, &result).code(), StatusCode::kInvalidArgument);
  ImageView bad_depth = view;
  bad_depth.bit_depth = 9;
  EXPECT_EQ(extractor.Extract(bad_depth, &result).code(), StatusCode::kInvalidArgument);
  bad_depth.bit_depth = 17;
  EXPECT_EQ(extractor.Extract(bad_depth, &result).code(), StatusCode::kInvalidArgument);
  ImageView short_stride = view;
  short_stride.stride_bytes = 7;
  EXPECT_EQ(extractor.Extract(short_stride, &result).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(extractor.Extract(view, nullptr).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(extractor.Extract(view, &result).ok());
}

TEST(StripeStatusTest, Names) {
  EXPECT_STREQ(StripeStatusName(StripeStatus::kValid), "valid");
  EXPECT_STREQ(StripeStatusName(StripeStatus::kNone), "none");
  EXPECT_STREQ(StripeStatusName(StripeStatus::kSaturated), "saturated");
  EXPECT_STREQ(StripeStatusName(StripeStatus::kTwoPeaks), "two_peaks");
  EXPECT_STREQ(StripeStatusName(StripeStatus::kTooWide), "too_wide");
}

// ---------------------------------------------------------------------------------------------
// Accuracy against the truth.

struct AccuracyCase {
  int bit_depth;
};

class StripeAccuracyTest : public ::testing::TestWithParam<AccuracyCase> {};

// Horizontal stripes at several sub-pixel offsets: every column within the bias bound plus 5
// noise sigmas, and the spread over columns no larger than the predicted noise.
TEST_P(StripeAccuracyTest, HorizontalStripeSubPixel) {
  const AccuracyCase param = GetParam();
  const double scale = param.bit_depth == 8 ? 1.0 : 16.0;
  const double sigma = 2.0, amplitude = 150.0 * scale, background = 15.0 * scale;
  const double noise = 2.0 * scale;
  StripeOptions o = ColumnOptions();
  o.min_peak *= scale;
  o.min_contrast *= scale;
  const ErrorModel model = ComputeErrorModel(sigma, amplitude, background, noise, o);
  // The model itself: eq. (7) with raw weights over the run above K = gmax / 2 is biased by up
  // to ~0.25 px for sigma = 2 px without noise (the run is 5 px long for most offsets), ~0.4 px
  // with an end pixel toggled. Over the window of +-3 sigma with the background removed and
  // the edge pixels by share, the truncation is of the tails only: 0.007 px at any offset and
  // toggle, and ~0.048 px of noise.
  EXPECT_LT(model.bias_bound, 0.02);
  EXPECT_LT(model.sigma_bound, 0.06);
  const double tolerance = model.bias_bound + 5 * model.sigma_bound;
  uint32_t seed = 1;
  int precise = 0;
  for (double offset : {0.0, 0.05, 0.13, 0.25, 0.37, 0.5, 0.62, 0.75, 0.88, 0.95}) {
    const double c = 61.0 + offset;
    TestImage img(200, 120, param.bit_depth, background);
    img.AddRowStripe([&](int) { return c; }, sigma, amplitude);
    img.AddNoise(noise, seed++);
    const StripeResult r = ExtractOrFail(o, img.View());
    ASSERT_EQ(r.center.size(), 200u);
    double sum = 0, sum2 = 0;
    for (int u = 0; u < 200; ++u) {
      ASSERT_EQ(r.status[u], StripeStatus::kValid) << "offset " << offset << " column " << u;
      EXPECT_NEAR(r.v(u), c, tolerance) << "offset " << offset << " column " << u;
      EXPECT_EQ(r.u(u), u);
      sum += r.center[u];
      sum2 += r.center[u] * r.center[u];
    }
    const double mean = sum / 200;
    const double std_dev = std::sqrt(std::max(sum2 / 200 - mean * mean, 0.0));
    // Where no pixel lies within 3.5 noise sigmas of K the run is the same in every column and
    // the scatter over columns is the centroid noise alone (1.5x: the estimate's own
    // uncertainty from 200 samples), and the mean is the noise-free centroid.
    const RefCandidate line =
        NoiseFreeCentroid(NoiseFreeProfile(c, 0.0, sigma, amplitude, background), o);
    if (RunMargin(NoiseFreeProfile(c, 0.0, sigma, amplitude, background), line) > 3.5 * noise) {
      ++precise;
      EXPECT_LT(std_dev, 1.5 * model.sigma_bound) << "offset " << offset;
      EXPECT_NEAR(mean, line.center, 5 * model.sigma_bound / std::sqrt(200.0) + 0.002)
          << "offset " << offset;
    }
  }
  EXPECT_GE(precise, 2);
}

INSTANTIATE_TEST_SUITE_P(DepthsAndWeights, StripeAccuracyTest,
                         ::testing::Values(AccuracyCase{8}, AccuracyCase{12}),
                         [](const ::testing::TestParamInfo<AccuracyCase>& info) {
                           return std::to_string(info.param.bit_depth) + "bit";
                         });

// Tilted stripes: the centre moves by `slope` per column, so the sub-pixel offset sweeps all
// values. The 3x3 median sees the stripe shifted by +-slope in the side columns, which changes
// the filtered profile (and the bias bound, computed for that slope).
TEST(StripeExtractorTest, TiltedStripesWithinBound) {
  const double sigma = 2.0, amplitude = 150.0, background = 15.0, noise = 2.0;
  const StripeOptions o = ColumnOptions();
  for (double slope : {0.05, -0.2, 0.45}) {
    const ErrorModel model = ComputeErrorModel(sigma, amplitude, background, noise, o, slope);
    EXPECT_LT(model.bias_bound, 0.02) << "slope " << slope;  // 0.007 px: the window's tails
    const double tolerance = model.bias_bound + 5 * model.sigma_bound;
    TestImage img(240, 200, 8, background);
    auto center = [&](int u) { return 100.0 + slope * (u - 120) + 0.01; };
    img.AddRowStripe(center, sigma, amplitude);
    img.AddNoise(noise, 7);
    const StripeResult r = ExtractOrFail(o, img.View());
    double worst = 0;
    for (int u = 0; u < 240; ++u) {
      ASSERT_EQ(r.status[u], StripeStatus::kValid) << "slope " << slope << " column " << u;
      worst = std::max(worst, std::abs(r.v(u) - center(u)));
    }
    EXPECT_LT(worst, tolerance) << "slope " << slope;
  }
}

// ---------------------------------------------------------------------------------------------
// Agreement with the naive reference.

TEST(StripeExtractorTest, MatchesReferenceOnCurvedStripe) {
  TestImage img(300, 260, 8, 15);
  img.AddRowStripe([](int u) { return 40.0 + 0.004 * (u - 20) * (u - 20) * 0.5; }, 2.0, 170);
  img.AddNoise(2.0, 3);
  // Spans ~130 rows over the width: groups are split, bands differ per group.
  EXPECT_GT(ExpectMatchesReference(img, ColumnOptions()), 290);
}

TEST(StripeExtractorTest, MatchesReferenceOnSteepStripeAndBorders) {
  TestImage img(150, 200, 8, 12);
  // Slope 1.2 px/column from the top border down to row ~180: every group is split.
  img.AddRowStripe([](int u) { return 1.0 + 1.2 * u; }, 1.5, 120);
  img.AddNoise(2.5, 4);
  EXPECT_GT(ExpectMatchesReference(img, ColumnOptions()), 140);
}

TEST(StripeExtractorTest, MatchesReferenceOn12BitWithAndWithoutMedian) {
  TestImage img(130, 90, 12, 200);
  img.AddRowStripe([](int u) { return 45.3 + 0.1 * u; }, 2.5, 2000);
  img.AddNoise(30, 5);
  StripeOptions o = ColumnOptions();
  o.min_peak = 300;
  o.min_contrast = 200;
  EXPECT_EQ(ExpectMatchesReference(img, o), 130);
  o.median_kernel = 1;
  EXPECT_EQ(ExpectMatchesReference(img, o), 130);
}

// Random scenes: one to three stripes (straight, tilted or curved, partly spanning the width),
// hot pixels, two-pixel defects, random options, odd sizes (partial blocks and groups), 8- and
// 12-bit. Every column must agree with the reference.
TEST(StripeExtractorTest, MatchesReferenceOnRandomScenes) {
  std::mt19937 rng(2024);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  int valid = 0, two_peaks = 0, none = 0, skipped = 0, missed = 0, columns = 0;
  for (int scene = 0; scene < 24; ++scene) {
    const int depth = scene % 3 == 2 ? 12 : 8;
    const double scale = depth == 8 ? 1.0 : 16.0;
    const int w = 40 + static_cast<int>(uni(rng) * 200);
    const int h = 30 + static_cast<int>(uni(rng) * 220);
    TestImage img(w, h, depth, (5 + 20 * uni(rng)) * scale);
    const int stripes = 1 + static_cast<int>(uni(rng) * 3);
    for (int i = 0; i < stripes; ++i) {
      const double c0 = uni(rng) * h, slope = (uni(rng) - 0.5) * 0.8;
      const double curve = (uni(rng) - 0.5) * 0.01;
      const int u0 = uni(rng) < 0.3 ? static_cast<int>(uni(rng) * w / 2) : 0;
      img.AddRowStripe(
          [&](int u) { return c0 + slope * (u - w / 2) + curve * (u - w / 2) * (u - w / 2); },
          0.8 + 3 * uni(rng), (40 + 160 * uni(rng)) * scale, u0, w);
    }
    img.AddNoise((0.5 + 2.5 * uni(rng)) * scale, 100 + scene);
    for (int i = 0; i < 10; ++i) {
      const int u = static_cast<int>(uni(rng) * w), v = static_cast<int>(uni(rng) * (h - 1));
      img.at(u, v) = img.max_value();
      if (i % 3 == 0) img.at(u, v + 1) = img.max_value();  // a two-pixel defect
    }
    StripeOptions o = ColumnOptions();
    o.threshold_ratio = 0.3 + 0.5 * uni(rng);
    o.min_peak = 20 * scale;
    o.min_contrast = 12 * scale;
    o.max_width_px = 10 + static_cast<int>(uni(rng) * 40);
    o.min_peak_separation_px = 1 + static_cast<int>(uni(rng) * 4);
    o.second_peak_ratio = uni(rng) < 0.3 ? 0.5 : 0.0;
    o.median_kernel = uni(rng) < 0.2 ? 1 : 3;
    SCOPED_TRACE("scene " + std::to_string(scene));
    valid += ExpectMatchesReference(img, o, 3 * scale, &skipped, &missed);
    columns += w;
    const StripeResult r = ExtractOrFail(o, img.View());
    for (StripeStatus st : r.status) {
      two_peaks += st == StripeStatus::kTwoPeaks;
      none += st == StripeStatus::kNone;
    }
  }
  EXPECT_LT(skipped, columns / 50);
  // Up to three stripes a scene, crossing each other: some lie 2 blocks from a brighter one.
  EXPECT_LT(missed, columns / 50);
  std::printf("%d columns: %d valid, %d skipped, %d missed\n", columns, valid, skipped, missed);
  // The scenes do exercise the different outcomes.
  EXPECT_GT(valid, 1000);
  EXPECT_GT(two_peaks, 100);
  EXPECT_GT(none, 50);
}

// ---------------------------------------------------------------------------------------------
// Statuses.

TEST(StripeExtractorTest, EmptyColumnsAreNone) {
  TestImage img(120, 80, 8, 15);
  img.AddRowStripe([](int) { return 40.3; }, 2.0, 150, 30, 90);  // columns 30..89 only
  img.AddNoise(2.0, 11);
  const StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
  for (int u = 0; u < 120; ++u) {
    // The 3x3 median reaches one column beyond the stripe's ends, which then still qualify.
    if (u < 29 || u > 90) {
      EXPECT_EQ(r.status[u], StripeStatus::kNone) << u;
      EXPECT_TRUE(std::isnan(r.center[u])) << u;
    } else if (u > 30 && u < 89) {
      EXPECT_EQ(r.status[u], StripeStatus::kValid) << u;
      EXPECT_NEAR(r.center[u], 40.3, 0.45) << u;
    }
  }
  EXPECT_GE(r.valid_count(), 58);
  EXPECT_LE(r.valid_count(), 62);
}

TEST(StripeExtractorTest, WeakStripesAreNone) {
  // min_peak: a stripe peaking at ~18 levels on a black background.
  TestImage dim(64, 50, 8, 0);
  dim.AddRowStripe([](int) { return 25.0; }, 2.0, 18);
  EXPECT_EQ(ExtractOrFail(ColumnOptions(), dim.View()).valid_count(), 0);
  // min_contrast: 10 levels over a background of 100 is no stripe, 30 levels is (K must then
  // lie above the background: k = 0.9).
  StripeOptions o = ColumnOptions();
  o.threshold_ratio = 0.9;
  TestImage faint(64, 50, 8, 100);
  faint.AddRowStripe([](int) { return 25.0; }, 2.0, 10);
  StripeResult r = ExtractOrFail(o, faint.View());
  EXPECT_EQ(r.valid_count(), 0);
  EXPECT_EQ(r.status[7], StripeStatus::kNone);
  TestImage visible(64, 50, 8, 100);
  visible.AddRowStripe([](int) { return 25.0; }, 2.0, 30);
  EXPECT_EQ(ExtractOrFail(o, visible.View()).valid_count(), 64);
  // K is taken above the local background, not as a fraction of the peak: with the default
  // k = 0.5 (K = k gmax would lie below the background and the run cover the column) the
  // stripe is as valid.
  r = ExtractOrFail(ColumnOptions(), visible.View());
  EXPECT_EQ(r.valid_count(), 64);
  EXPECT_NEAR(r.center[7], 25.0, 0.1);
}

TEST(StripeExtractorTest, SaturatedStripe) {
  TestImage img(60, 60, 8, 15);
  img.AddRowStripe([](int) { return 30.2; }, 2.0, 400);  // clipped at 255 over ~3 rows
  StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
  for (int u = 0; u < 60; ++u) {
    EXPECT_EQ(r.status[u], StripeStatus::kSaturated) << u;
    EXPECT_TRUE(std::isnan(r.center[u]));
    EXPECT_EQ(r.peak[u], 255);
  }
  // Peak ~250: valid; unless the caller sets a lower saturation level.
  TestImage bright(60, 60, 8, 15);
  bright.AddRowStripe([](int) { return 30.0; }, 2.0, 235 / PixelGaussian(0, 2.0, 1.0));
  EXPECT_EQ(ExtractOrFail(ColumnOptions(), bright.View()).valid_count(), 60);
  StripeOptions o = ColumnOptions();
  o.saturation_level = 200;
  r = ExtractOrFail(o, bright.View());
  EXPECT_EQ(r.valid_count(), 0);
  EXPECT_EQ(r.status[10], StripeStatus::kSaturated);
}

TEST(StripeExtractorTest, SaturationUsesTheImageBitDepth) {
  // 12-bit: a peak of ~1000 is far from full scale (4095) although above 255.
  TestImage img(60, 60, 12, 200);
  img.AddRowStripe([](int) { return 30.0; }, 2.0, 800);
  StripeOptions o = ColumnOptions();
  o.min_peak = 300;
  EXPECT_EQ(ExtractOrFail(o, img.View()).valid_count(), 60);
  TestImage clipped(60, 60, 12, 200);
  clipped.AddRowStripe([](int) { return 30.0; }, 2.0, 6000);
  const StripeResult r = ExtractOrFail(o, clipped.View());
  EXPECT_EQ(r.status[30], StripeStatus::kSaturated);
  EXPECT_EQ(r.peak[30], 4095);
}

TEST(StripeExtractorTest, TwoStripesInAColumnAreTwoPeaks) {
  for (double distance : {9.0, 70.0}) {
    TestImage img(100, 160, 8, 15);
    img.AddRowStripe([](int) { return 40.0; }, 1.5, 150);
    img.AddRowStripe([&](int) { return 40.0 + distance; }, 1.5, 120, 50, 100);  // right half
    img.AddNoise(2.0, 13);
    const StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
    for (int u = 0; u < 100; ++u) {
      if (u < 49) {
        EXPECT_EQ(r.status[u], StripeStatus::kValid) << distance << " " << u;
      } else if (u > 50) {
        EXPECT_EQ(r.status[u], StripeStatus::kTwoPeaks) << distance << " " << u;
      }
    }
    // A weak second stripe (a reflection at a third of the peak) is a second stripe too: the
    // extractor cannot tell which of the two the surface is. Close to the stripe it sits on
    // its tail and some columns find it lopsided (bad_shape, not a stripe): those keep the
    // stripe, unmoved by it.
    TestImage weak(100, 160, 8, 15);
    weak.AddRowStripe([](int) { return 40.0; }, 1.5, 150);
    weak.AddRowStripe([&](int) { return 40.0 + distance; }, 1.5, 50);
    weak.AddNoise(2.0, 14);
    StripeResult w = ExtractOrFail(ColumnOptions(), weak.View());
    int two = 0;
    for (int u = 0; u < 100; ++u) {
      two += w.status[u] == StripeStatus::kTwoPeaks;
      if (w.status[u] == StripeStatus::kValid) {
        EXPECT_NEAR(w.center[u], 40.0, 0.3) << u;
      }
    }
    // Far from the stripe, every column; on its tail, at least a third.
    EXPECT_GE(two, distance > 20 ? 100 : 34) << distance;
    EXPECT_EQ(ExpectMatchesReference(weak, ColumnOptions()), 100 - two) << distance;
    // Told that a peak under half the stripe's is not one (second_peak_ratio), it is ignored.
    StripeOptions lenient = ColumnOptions();
    lenient.second_peak_ratio = 0.5;
    w = ExtractOrFail(lenient, weak.View());
    EXPECT_EQ(w.valid_count(), 100) << distance;
    for (int u = 0; u < 100; ++u) EXPECT_NEAR(w.center[u], 40.0, 0.3) << u;
  }
}

TEST(StripeExtractorTest, LitSurfaceIsNotASecondStripe) {
  // A weak stripe (filtered peak ~51) on a dark surface (15), and in the same columns a part's
  // face lit by ambient light (35, above K ~33 and brighter than the stripe's K): a broad
  // plateau, which is no stripe; or a narrow patch of it (a corner, 6 rows), which in one
  // gray plane is a line as much as the stripe is.
  TestImage img(60, 200, 8, 15);
  img.AddRowStripe([](int) { return 150.0; }, 1.5, 45);
  for (int u = 0; u < 60; ++u) {
    for (int v = 20; v < 100; ++v) img.at(u, v) = u < 30 ? 35 : 15;  // the face, 80 rows
    if (u >= 30) {
      for (int v = 60; v < 66; ++v) img.at(u, v) = 35;  // its corner: 6 rows, stripe-wide
    }
  }
  img.AddNoise(1.5, 23);
  StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
  // The stripe's centre at 150, unaffected by the face.
  for (int u = 0; u < 30; ++u) {
    EXPECT_EQ(r.status[u], StripeStatus::kValid) << u;
    EXPECT_NEAR(r.center[u], 150.0, 0.3) << u;
  }
  for (int u = 30; u < 60; ++u) EXPECT_EQ(r.status[u], StripeStatus::kTwoPeaks) << u;
  EXPECT_EQ(ExpectMatchesReference(img, ColumnOptions()), 30);
  // The patch's contrast (~20) is ~0.55 of the stripe's: told to ignore peaks under 0.8 of
  // the stronger, every column has its stripe.
  StripeOptions lenient = ColumnOptions();
  lenient.second_peak_ratio = 0.8;
  r = ExtractOrFail(lenient, img.View());
  EXPECT_EQ(r.valid_count(), 60);
  for (int u = 0; u < 60; ++u) EXPECT_NEAR(r.center[u], 150.0, 0.3) << u;
  EXPECT_EQ(ExpectMatchesReference(img, lenient), 60);
}

TEST(StripeExtractorTest, ShortDipsInsideTheRunAreBridged) {
  // A wide flat-topped stripe with one dark row in its middle (a scratch on the part): with the
  // default separation (3) the two halves are one run; with separation 1 they are two peaks.
  TestImage img(50, 80, 8, 15);
  img.AddRowStripe([](int) { return 36.0; }, 1.2, 150);
  img.AddRowStripe([](int) { return 42.0; }, 1.2, 150);
  for (int u = 0; u < 50; ++u) {
    for (int v = 38; v <= 40; ++v) img.at(u, v) = 20;  // the three rows between the peaks
  }
  StripeOptions o = ColumnOptions();
  o.median_kernel = 1;
  o.min_peak_separation_px = 4;
  StripeResult r = ExtractOrFail(o, img.View());
  EXPECT_EQ(r.valid_count(), 50);
  EXPECT_NEAR(r.center[20], 39.0, 0.05);
  EXPECT_GE(r.width_px[20], 9);
  o.min_peak_separation_px = 3;
  r = ExtractOrFail(o, img.View());
  EXPECT_EQ(r.status[20], StripeStatus::kTwoPeaks);
}

TEST(StripeExtractorTest, TooWideStripe) {
  TestImage img(80, 200, 8, 15);
  img.AddRowStripe([](int u) { return 100.0 + 0.1 * u; }, 12.0, 150);  // run above K ~28 px
  img.AddNoise(1.0, 17);
  StripeOptions o = ColumnOptions();
  o.max_width_px = 20;
  StripeResult r = ExtractOrFail(o, img.View());
  for (int u = 0; u < 80; ++u) EXPECT_EQ(r.status[u], StripeStatus::kTooWide) << u;
  // Allowed wider, the same stripe is valid; its run is longer than the band pass 2 starts
  // with, so this goes through the wide retry.
  o.max_width_px = 40;
  r = ExtractOrFail(o, img.View());
  EXPECT_EQ(r.valid_count(), 80);
  EXPECT_NEAR(r.center[40], 104.0, 0.3);
  EXPECT_GE(r.width_px[40], 24);
  EXPECT_EQ(ExpectMatchesReference(img, o), 80);
}

TEST(StripeExtractorTest, HotPixelsAreIgnoredByTheMedian) {
  TestImage clean(90, 70, 8, 15);
  clean.AddRowStripe([](int u) { return 30.0 + 0.05 * u; }, 2.0, 150, 0, 60);
  clean.AddNoise(2.0, 19);
  TestImage hot = clean;
  hot.at(75, 10) = 250;  // in an empty column
  hot.at(20, 12) = 250;  // above the stripe
  hot.at(40, 55) = 250;  // below the stripe
  hot.at(10, 30) = 0;    // a dead pixel at the stripe's peak
  const StripeResult a = ExtractOrFail(ColumnOptions(), clean.View());
  const StripeResult b = ExtractOrFail(ColumnOptions(), hot.View());
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(b.status[75], StripeStatus::kNone);
  EXPECT_EQ(b.valid_count(), 60);
  for (int u = 0; u < 90; ++u) {
    if (a.status[u] == StripeStatus::kValid) {
      // The dead pixel moves the 3x3 median of its neighbours by a rank: ~ the centre's noise
      // (0.02-0.03 px here, with weights g - K).
      EXPECT_NEAR(a.center[u], b.center[u], 0.05) << u;
    }
  }
  // Without the median the hot pixels remain in the profiles.
  StripeOptions raw = ColumnOptions();
  raw.median_kernel = 1;
  const StripeResult c = ExtractOrFail(raw, hot.View());
  // A hot pixel alone is one pixel wide: narrower than any beam the optics blur, not a
  // stripe. In an empty column it is not taken for one; above the stripe it leaves it valid.
  EXPECT_EQ(c.status[75], StripeStatus::kBadShape);
  EXPECT_EQ(c.status[20], StripeStatus::kValid);
  EXPECT_NEAR(c.center[20], b.center[20], 0.3);
}

TEST(StripeExtractorTest, DeadColumnIsFilledByTheMedian) {
  // A dead sensor column crossing the stripe: the 3x3 median restores the stripe there (six of
  // the nine pixels are lit), although the column itself never sees it.
  TestImage img(40, 60, 8, 15);
  img.AddRowStripe([](int) { return 30.0; }, 2.0, 150);
  img.AddNoise(1.0, 43);
  for (int v = 0; v < 60; ++v) img.at(17, v) = 0;
  const StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
  EXPECT_EQ(r.status[17], StripeStatus::kValid);
  EXPECT_NEAR(r.center[17], 30.0, 0.1);
  EXPECT_EQ(ExpectMatchesReference(img, ColumnOptions()), 40);
}

TEST(StripeExtractorTest, TwoPixelDefectAwayFromTheStripe) {
  // A vertical two-pixel defect survives the vertical median of pass 1 and outshines the stripe
  // there, but not the 3x3 median: the stripe must still be found.
  TestImage img(70, 120, 8, 15);
  img.AddRowStripe([](int) { return 80.0; }, 2.0, 120);
  img.AddNoise(1.5, 23);
  img.at(33, 20) = img.at(33, 21) = 255;
  const StripeResult r = ExtractOrFail(ColumnOptions(), img.View());
  EXPECT_EQ(r.status[33], StripeStatus::kValid);
  EXPECT_NEAR(r.center[33], 80.0, 0.45);
  EXPECT_EQ(ExpectMatchesReference(img, ColumnOptions()), 70);
}

// ---------------------------------------------------------------------------------------------
// The window: where the light plane lets the stripe be.

TEST(StripeExtractorTest, AWindowKeepsOutLightFromElsewhere) {
  TestImage img(80, 200, 8, 15);
  img.AddRowStripe([](int) { return 120.3; }, 1.5, 100);  // the stripe
  img.AddRowStripe([](int) { return 50.0; }, 1.5, 150);   // a brighter reflection
  img.AddNoise(1.5, 51);
  const ImageView view = img.View();
  StripeExtractor extractor(ColumnOptions());
  StripeResult r;
  auto window = [](float lo, float hi) {
    StripeWindow w;
    w.lo.assign(80, lo);
    w.hi.assign(80, hi);
    return w;
  };
  // No window, or NaN limits (anywhere): two stripes in every column.
  ASSERT_TRUE(extractor.Extract(view, &r).ok());
  EXPECT_EQ(r.valid_count(), 0);
  EXPECT_EQ(r.status[40], StripeStatus::kTwoPeaks);
  StripeWindow w = window(NAN, NAN);
  ASSERT_TRUE(extractor.Extract(view, &r, &w).ok());
  EXPECT_EQ(r.status[40], StripeStatus::kTwoPeaks);
  // The plane's rows: the stripe, not the brighter light outside them.
  w = window(100.0f, 140.0f);
  ASSERT_TRUE(extractor.Extract(view, &r, &w).ok());
  EXPECT_EQ(r.valid_count(), 80);
  EXPECT_NEAR(r.center[40], 120.3, 0.2);
  // A window holding neither (its edge half a pixel from the stripe's peak row 120), an empty
  // one (lo > hi), and one under a pixel wide: no stripe, never a valid line without a centre.
  for (const auto& [lo, hi] :
       {std::pair{120.5f, 190.0f}, std::pair{10.0f, 5.0f}, std::pair{80.2f, 80.8f}}) {
    w = window(lo, hi);
    ASSERT_TRUE(extractor.Extract(view, &r, &w).ok());
    for (int u = 0; u < 80; ++u) {
      EXPECT_EQ(r.status[u], StripeStatus::kNone) << lo << ".." << hi << " column " << u;
      EXPECT_TRUE(std::isnan(r.center[u]));
    }
  }
  // Refused: a window of another size, and a window with the direction left to the image.
  w = window(100.0f, 140.0f);
  w.hi.pop_back();
  EXPECT_EQ(extractor.Extract(view, &r, &w).code(), StatusCode::kInvalidArgument);
  StripeExtractor automatic(StripeOptions{});
  w = window(100.0f, 140.0f);
  const Status st = automatic.Extract(view, &r, &w);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("auto"), std::string::npos) << st.message();
}

// ---------------------------------------------------------------------------------------------
// Directions.

TEST(StripeExtractorTest, RowsDirectionMatchesColumnsOnTransposedImage) {
  for (int depth : {8, 12}) {
    const double scale = depth == 8 ? 1 : 16;
    TestImage img(150, 110, depth, 15 * scale);
    img.AddRowStripe([](int u) { return 50.0 + 0.2 * u - 0.001 * u * u; }, 2.0, 150 * scale);
    img.AddNoise(2.0 * scale, 29);
    StripeOptions o = ColumnOptions();
    o.min_peak *= scale;
    o.min_contrast *= scale;
    const StripeResult cols = ExtractOrFail(o, img.View());
    TestImage t = img.Transposed();
    o.direction = StripeDirection::kRows;
    const StripeResult rows = ExtractOrFail(o, t.View());
    ASSERT_EQ(rows.direction, StripeDirection::kRows);
    ASSERT_EQ(rows.center.size(), 150u);  // one per row of the transposed image
    EXPECT_EQ(rows.status, cols.status);
    EXPECT_EQ(rows.peak, cols.peak);
    EXPECT_GT(rows.valid_count(), 145);
    for (int i = 0; i < 150; ++i) {
      if (cols.status[i] != StripeStatus::kValid) continue;
      EXPECT_EQ(rows.center[i], cols.center[i]) << i;
      // Row i of the transposed image: the centre is a column coordinate u.
      EXPECT_EQ(rows.v(i), i);
      EXPECT_EQ(rows.u(i), cols.v(i));
    }
  }
}

TEST(StripeDirectionTest, EstimatesThePrincipalAxis) {
  struct Case {
    double angle;
    StripeDirection expected;
  };
  for (const Case& c : {Case{0, StripeDirection::kColumns}, Case{30, StripeDirection::kColumns},
                        Case{-40, StripeDirection::kColumns}, Case{50, StripeDirection::kRows},
                        Case{90, StripeDirection::kRows}, Case{-70, StripeDirection::kRows}}) {
    for (int depth : {8, 12}) {
      // Landscape and portrait frames: the answer must not follow the frame's shape.
      for (bool portrait : {false, true}) {
        TestImage img(portrait ? 240 : 320, portrait ? 320 : 240, depth, depth == 8 ? 15 : 240);
        img.AddLine(img.width / 2.0, img.height / 2.0, c.angle, 2.0, depth == 8 ? 150 : 2400);
        img.AddNoise(depth == 8 ? 2 : 32, 31);
        img.at(5, 5) = img.max_value();  // a hot pixel does not decide
        EXPECT_EQ(EstimateStripeDirection(img.View()), c.expected)
            << "angle " << c.angle << " depth " << depth << " portrait " << portrait;
      }
    }
  }
  TestImage black(64, 48, 8, 0);
  EXPECT_EQ(EstimateStripeDirection(black.View()), StripeDirection::kColumns);
  EXPECT_EQ(EstimateStripeDirection(ImageView{}), StripeDirection::kColumns);
}

// A white board (a plateau far wider than a stripe, brighter than it) beside a thin stripe:
// the direction is the stripe's, whatever the board's shape.
TEST(StripeDirectionTest, ABrightBoardDoesNotDecide) {
  for (bool tall_board : {true, false}) {
    TestImage img(320, 240, 8, 15);
    img.AddRowStripe([](int u) { return 60.0 + 0.05 * u; }, 1.5, 120);  // runs left-right
    for (int v = 100; v < 230; ++v) {
      for (int u = 40; u < (tall_board ? 120 : 300); ++u) img.at(u, v) += 200;
    }
    img.AddNoise(2, 33);
    EXPECT_EQ(EstimateStripeDirection(img.View()), StripeDirection::kColumns) << tall_board;
    const TestImage t = img.Transposed();
    TestImage tt = t;
    EXPECT_EQ(EstimateStripeDirection(tt.View()), StripeDirection::kRows) << tall_board;
  }
}

TEST(StripeExtractorTest, AutoDirection) {
  TestImage img(200, 150, 8, 15);
  img.AddColumnStripe([](int v) { return 80.0 + 0.1 * v; }, 2.0, 150);
  img.AddNoise(2.0, 37);
  const StripeResult r = ExtractOrFail(StripeOptions{}, img.View());  // default: kAuto
  EXPECT_EQ(r.direction, StripeDirection::kRows);
  ASSERT_EQ(r.center.size(), 150u);
  EXPECT_EQ(r.valid_count(), 150);
  EXPECT_NEAR(r.u(75), 87.5, 0.45);
  EXPECT_EQ(r.v(75), 75);

  TestImage flat(200, 150, 8, 15);
  flat.AddRowStripe([](int u) { return 60.0 + 0.1 * u; }, 2.0, 150);
  const StripeResult f = ExtractOrFail(StripeOptions{}, flat.View());
  EXPECT_EQ(f.direction, StripeDirection::kColumns);
  EXPECT_EQ(f.center.size(), 200u);
}

// ---------------------------------------------------------------------------------------------
// Reuse and odd sizes.

TEST(StripeExtractorTest, ReusedExtractorGivesTheSameResults) {
  StripeExtractor extractor(ColumnOptions());
  StripeResult reused;
  for (int i = 0; i < 6; ++i) {
    const int depth = i % 2 == 0 ? 8 : 12;
    const double scale = depth == 8 ? 1 : 16;
    TestImage img(60 + 37 * i, 200 - 25 * i, depth, 15 * scale);
    img.AddRowStripe([&](int u) { return 20.0 + 10 * i + 0.1 * u; }, 2.0, 150 * scale);
    img.AddNoise(2 * scale, 41 + i);
    const ImageView view = img.View();
    ASSERT_TRUE(extractor.Extract(view, &reused).ok());
    StripeOptions o = ColumnOptions();
    const StripeResult fresh = ExtractOrFail(o, view);
    EXPECT_EQ(reused.status, fresh.status) << i;
    EXPECT_EQ(reused.peak, fresh.peak) << i;
    EXPECT_EQ(reused.center.size(), static_cast<size_t>(img.width));
    for (size_t u = 0; u < fresh.center.size(); ++u) {
      if (fresh.status[u] == StripeStatus::kValid) {
        EXPECT_EQ(reused.center[u], fresh.center[u]);
      }
    }
  }
}

TEST(StripeExtractorTest, TinyImages) {
  for (auto [w, h] : {std::pair{1, 1}, {1, 7}, {7, 1}, {2, 2}, {3, 3}, {65, 2}, {2, 65}}) {
    TestImage img(w, h, 8, 15);
    img.at(0, h / 2) = 200;
    if (w > 1) img.at(1, h / 2) = 200;
    StripeExtractor extractor(ColumnOptions());
    StripeResult r;
    ASSERT_TRUE(extractor.Extract(img.View(), &r).ok()) << w << "x" << h;
    EXPECT_EQ(r.center.size(), static_cast<size_t>(w));
    EXPECT_EQ(r.status.size(), static_cast<size_t>(w));
    EXPECT_EQ(r.peak.size(), static_cast<size_t>(w));
    EXPECT_EQ(r.width_px.size(), static_cast<size_t>(w));
  }
  // A stripe along the top border: the run is cut by the border, still one valid centre.
  TestImage top(40, 30, 8, 15);
  top.AddRowStripe([](int) { return 0.0; }, 1.5, 150);
  EXPECT_EQ(ExpectMatchesReference(top, ColumnOptions()), 40);
}

}  // namespace
}  // namespace insitu::vision
