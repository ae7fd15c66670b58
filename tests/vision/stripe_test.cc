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
// The naive reference: the method of stripe.h applied literally, column by column.

struct RefLine {
  StripeStatus status = StripeStatus::kNone;
  double center = NAN;
  int peak = 0;
  int width = 0;
  double contrast = 0;  // gmax - background (median of the whole profile)
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

RefLine RefColumn(const std::vector<int>& g, const std::vector<int>& raw, const StripeOptions& o,
                  int saturation) {
  const int n = static_cast<int>(g.size());
  RefLine out;
  const int rp = static_cast<int>(std::max_element(g.begin(), g.end()) - g.begin());
  const int gmax = g[rp];
  out.peak = gmax;
  std::vector<int> sorted = raw;
  std::nth_element(sorted.begin(), sorted.begin() + (n - 1) / 2, sorted.end());
  const double background = sorted[(n - 1) / 2];
  out.contrast = gmax - background;
  if (gmax < o.min_peak || gmax - background < o.min_contrast) return out;
  const double k = o.threshold_ratio * gmax;
  int re = rp;
  for (int r = rp + 1, gap = 0; r < n; ++r) {
    if (g[r] > k) {
      re = r;
      gap = 0;
      if (re - rp >= o.max_width_px) break;
    } else if (++gap >= o.min_peak_separation_px) {
      break;
    }
  }
  int rs = rp;
  for (int r = rp - 1, gap = 0; r >= 0; --r) {
    if (g[r] > k) {
      rs = r;
      gap = 0;
      if (rp - rs >= o.max_width_px) break;
    } else if (++gap >= o.min_peak_separation_px) {
      break;
    }
  }
  out.width = re - rs + 1;
  bool saturated = false;
  for (int r = rs; r <= re; ++r) saturated = saturated || raw[r] >= saturation;
  // Another stripe: a run above K outside rs..re (dips shorter than min_peak_separation_px
  // bridged), at most max_width_px long, peaking at second_peak_ratio * gmax or more.
  bool other = false;
  for (int r = 0; r < n;) {
    if (g[r] <= k) {
      ++r;
      continue;
    }
    int start = r, last = r, peak = g[r];
    for (int gap = 0; r < n && gap < o.min_peak_separation_px; ++r) {
      if (g[r] > k) {
        last = r;
        peak = std::max(peak, g[r]);
        gap = 0;
      } else {
        ++gap;
      }
    }
    r = last + 1;
    other = other || ((last < rs || start > re) && last - start + 1 <= o.max_width_px &&
                      peak >= o.second_peak_ratio * gmax);
  }
  if (saturated) {
    out.status = StripeStatus::kSaturated;
  } else if (out.width > o.max_width_px) {
    out.status = StripeStatus::kTooWide;
  } else if (other) {
    out.status = StripeStatus::kTwoPeaks;
  } else {
    double s0 = 0, s1 = 0;
    for (int r = rs; r <= re; ++r) {
      const double w = o.subtract_threshold ? std::max(g[r] - k, 0.0) : g[r];
      s0 += w;
      s1 += w * r;
    }
    if (s0 > 0) {
      out.status = StripeStatus::kValid;
      out.center = s1 / s0;
    }
  }
  return out;
}

// Reference result for every column of a kColumns image.
std::vector<RefLine> Reference(const TestImage& img, const StripeOptions& o) {
  const std::vector<int> filtered = NaiveMedian3x3(img, o.median_kernel);
  const int saturation = o.saturation_level > 0 ? o.saturation_level : img.max_value();
  std::vector<RefLine> out;
  for (int u = 0; u < img.width; ++u) {
    std::vector<int> g(img.height), raw(img.height);
    for (int v = 0; v < img.height; ++v) {
      g[v] = filtered[v * img.width + u];
      raw[v] = img.Quantized(u, v);
    }
    out.push_back(RefColumn(g, raw, o, saturation));
  }
  return out;
}

// Exact agreement with the reference on every column; returns the number of valid columns.
// The extractor estimates the background from a sample of rows (see stripe.cc), so a column
// whose contrast lies within `contrast_tolerance` of min_contrast may go either way; those are
// skipped (and counted in *skipped).
int ExpectMatchesReference(TestImage& img, const StripeOptions& o, double contrast_tolerance = 0,
                           int* skipped = nullptr) {
  const StripeResult r = ExtractOrFail(o, img.View());
  const std::vector<RefLine> ref = Reference(img, o);
  EXPECT_EQ(r.direction, StripeDirection::kColumns);
  EXPECT_EQ(r.status.size(), ref.size());
  int valid = 0;
  for (int u = 0; u < img.width && u < static_cast<int>(r.status.size()); ++u) {
    if (std::abs(ref[u].contrast - o.min_contrast) <= contrast_tolerance) {
      if (skipped != nullptr) ++*skipped;
      continue;
    }
    // Status names print readably; the context helps to rebuild a failing random scene.
    EXPECT_EQ(StripeStatusName(r.status[u]), std::string(StripeStatusName(ref[u].status)))
        << "column " << u << " of " << img.width << "x" << img.height << ", peak " << r.peak[u]
        << " (reference " << ref[u].peak << "), run " << int{r.width_px[u]} << " (" << ref[u].width
        << "), k " << o.threshold_ratio << ", separation " << o.min_peak_separation_px
        << ", max width " << o.max_width_px << ", kernel " << o.median_kernel;
    if (ref[u].status == StripeStatus::kNone) continue;
    EXPECT_EQ(r.peak[u], ref[u].peak) << "column " << u;
    if (ref[u].status != StripeStatus::kValid) continue;
    ++valid;
    EXPECT_NEAR(r.center[u], ref[u].center, 1e-4) << "column " << u;
    EXPECT_EQ(r.width_px[u], ref[u].width) << "column " << u;
  }
  return valid;
}

// ---------------------------------------------------------------------------------------------
// The error model of eq. (7), from the noise-free profile.
//
// A stripe with centre c + slope * du in column u + du: the 3x3 median of the noise-free image at
// (u, v) is the median of the 9 values p(v + dv - c - slope * du), which for slope 0 is the
// vertical 3-median of the 1-D profile.

struct ErrorModel {
  double bias_bound = 0;   // max over the sub-pixel offset of |U - c| without noise
  double sigma_bound = 0;  // max over the offset of the centroid's noise std (see below)
};

struct NoiseFreeLine {
  int rs = 0, re = 0;  // the run above K
  double k = 0;
  double center = 0;  // U of eq. (7)
  double spread = 0;  // sum over the run of (v_i - U)^2
  double weight = 0;  // sum over the run of the weights
  double margin = 0;  // min over the profile of |g_i - K|: noise below this keeps the run fixed
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

void Centroid(const std::vector<double>& g, const StripeOptions& o, NoiseFreeLine* line) {
  double s1 = 0;
  line->weight = 0;
  for (int v = line->rs; v <= line->re; ++v) {
    const double w = o.subtract_threshold ? g[v] - line->k : g[v];
    line->weight += w;
    s1 += w * v;
  }
  line->center = s1 / line->weight;
  line->spread = 0;
  for (int v = line->rs; v <= line->re; ++v) {
    line->spread += (v - line->center) * (v - line->center);
  }
}

NoiseFreeLine NoiseFreeCentroid(const std::vector<double>& g, const StripeOptions& o) {
  const int rp = static_cast<int>(std::max_element(g.begin(), g.end()) - g.begin());
  NoiseFreeLine line;
  line.k = o.threshold_ratio * g[rp];
  line.rs = line.re = rp;
  while (g[line.rs - 1] > line.k) --line.rs;
  while (g[line.re + 1] > line.k) ++line.re;
  Centroid(g, o, &line);
  line.margin = std::numeric_limits<double>::max();
  for (double x : g) line.margin = std::min(line.margin, std::abs(x - line.k));
  return line;
}

// Centroid noise: U = sum(g_i v_i) / sum(g_i); with independent noise e_i of std n on g_i,
// dU/de_i = (v_i - U) / sum(g), so std(U) = n sqrt(sum (v_i - U)^2) / sum(g_i). The 3x3 median
// reduces the per-pixel noise (to ~0.4 n on a flat patch) but correlates neighbouring rows
// (shared pixels); the raw n is used as a conservative value, plus 1/12 LSB^2 of quantization.
//
// Bias: the deterministic truncation error of eq. (7), i.e. the run above K does not extend
// symmetrically around c (its ends are whole pixels), plus the pull of the background inside
// the run. Noise can move a pixel whose filtered value lies close to K across it; the run then
// gains or loses that end pixel (at offset 0.5, for one, the symmetric 6-pixel run loses an end
// and U moves by 0.32 px). So the bound is the largest |U - c| over all offsets and over the
// runs with each end pixel within 5 noise sigmas of K (K itself is noisy) toggled.
ErrorModel ComputeErrorModel(double sigma, double amplitude, double background, double noise,
                             const StripeOptions& o, double slope = 0.0) {
  ErrorModel m;
  const double n_eff = std::sqrt(noise * noise + 1.0 / 12.0);
  for (int step = 0; step < 200; ++step) {
    const double c = 50.0 + step / 200.0;
    const std::vector<double> g = NoiseFreeProfile(c, slope, sigma, amplitude, background);
    const NoiseFreeLine base = NoiseFreeCentroid(g, o);
    auto near_k = [&](int v) { return std::abs(g[v] - base.k) < 5 * n_eff; };
    for (int ds = -1; ds <= 1; ++ds) {
      for (int de = -1; de <= 1; ++de) {
        NoiseFreeLine line = base;
        if (ds != 0 && !near_k(ds < 0 ? base.rs - 1 : base.rs)) continue;
        if (de != 0 && !near_k(de > 0 ? base.re + 1 : base.re)) continue;
        line.rs += ds;
        line.re += de;
        if (line.rs > line.re) continue;
        Centroid(g, o, &line);
        m.bias_bound = std::max(m.bias_bound, std::abs(line.center - c));
        m.sigma_bound = std::max(m.sigma_bound, n_eff * std::sqrt(line.spread) / line.weight);
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
  bool subtract_threshold;
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
  o.subtract_threshold = param.subtract_threshold;
  o.min_peak *= scale;
  o.min_contrast *= scale;
  const ErrorModel model = ComputeErrorModel(sigma, amplitude, background, noise, o);
  // The model itself: eq. (7) with K = gmax / 2 is biased by up to ~0.25 px for sigma = 2 px
  // without noise (the run is 5 px long for most offsets), ~0.4 px with an end pixel toggled;
  // weighting by g - K gives the end pixels (g ~ K) almost no weight and removes most of it.
  if (param.subtract_threshold) {
    EXPECT_LT(model.bias_bound, 0.12);
  } else {
    EXPECT_GT(model.bias_bound, 0.2);
    EXPECT_LT(model.bias_bound, 0.45);
  }
  EXPECT_LT(model.sigma_bound, 0.02 * (param.subtract_threshold ? 3 : 1));
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
    const NoiseFreeLine line =
        NoiseFreeCentroid(NoiseFreeProfile(c, 0.0, sigma, amplitude, background), o);
    if (line.margin > 3.5 * noise) {
      ++precise;
      EXPECT_LT(std_dev, 1.5 * model.sigma_bound) << "offset " << offset;
      EXPECT_NEAR(mean, line.center, 5 * model.sigma_bound / std::sqrt(200.0) + 0.002)
          << "offset " << offset;
    }
  }
  EXPECT_GE(precise, 2);
}

INSTANTIATE_TEST_SUITE_P(DepthsAndWeights, StripeAccuracyTest,
                         ::testing::Values(AccuracyCase{8, false}, AccuracyCase{8, true},
                                           AccuracyCase{12, false}, AccuracyCase{12, true}),
                         [](const ::testing::TestParamInfo<AccuracyCase>& info) {
                           return std::to_string(info.param.bit_depth) + "bit" +
                                  (info.param.subtract_threshold ? "SubtractK" : "Plain");
                         });

// Tilted stripes: the centre moves by `slope` per column, so the sub-pixel offset sweeps all
// values. The 3x3 median sees the stripe shifted by +-slope in the side columns, which changes
// the filtered profile (and the bias bound, computed for that slope).
TEST(StripeExtractorTest, TiltedStripesWithinBound) {
  const double sigma = 2.0, amplitude = 150.0, background = 15.0, noise = 2.0;
  const StripeOptions o = ColumnOptions();
  for (double slope : {0.05, -0.2, 0.45}) {
    const ErrorModel model = ComputeErrorModel(sigma, amplitude, background, noise, o, slope);
    EXPECT_LT(model.bias_bound, 0.45) << "slope " << slope;
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

TEST(StripeExtractorTest, MatchesReferenceWithSubtractThresholdAndNoMedian) {
  TestImage img(130, 90, 12, 200);
  img.AddRowStripe([](int u) { return 45.3 + 0.1 * u; }, 2.5, 2000);
  img.AddNoise(30, 5);
  StripeOptions o = ColumnOptions();
  o.subtract_threshold = true;
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
  int valid = 0, two_peaks = 0, none = 0, skipped = 0, columns = 0;
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
    o.subtract_threshold = uni(rng) < 0.3;
    o.median_kernel = uni(rng) < 0.2 ? 1 : 3;
    SCOPED_TRACE("scene " + std::to_string(scene));
    valid += ExpectMatchesReference(img, o, 3 * scale, &skipped);
    columns += w;
    const StripeResult r = ExtractOrFail(o, img.View());
    for (StripeStatus st : r.status) {
      two_peaks += st == StripeStatus::kTwoPeaks;
      none += st == StripeStatus::kNone;
    }
  }
  EXPECT_LT(skipped, columns / 50);
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
  // With the default k = 0.5, K lies below the background and the run covers the column.
  EXPECT_EQ(ExtractOrFail(ColumnOptions(), visible.View()).status[7], StripeStatus::kTooWide);
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
    // The second stripe below K (a weak reflection) does not count.
    TestImage weak(100, 160, 8, 15);
    weak.AddRowStripe([](int) { return 40.0; }, 1.5, 150);
    weak.AddRowStripe([&](int) { return 40.0 + distance; }, 1.5, 50);
    weak.AddNoise(2.0, 14);
    EXPECT_EQ(ExtractOrFail(ColumnOptions(), weak.View()).valid_count(), 100) << distance;
  }
}

TEST(StripeExtractorTest, LitSurfaceIsNotASecondStripe) {
  // A weak stripe (filtered peak ~51) on a dark surface (15), and in the same columns a part's
  // face lit by ambient light (35, above K ~25 but under 0.8 gmax): a broad plateau, or a
  // narrow patch of it (a corner).
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
  EXPECT_EQ(r.valid_count(), 60);
  // The stripe's centre at 150, unaffected by the face.
  for (int u = 0; u < 60; ++u) EXPECT_NEAR(r.center[u], 150.0, 0.3) << u;
  EXPECT_EQ(ExpectMatchesReference(img, ColumnOptions()), 60);
  // Counting every other run, the corner columns are ambiguous; the broad face never is.
  StripeOptions strict = ColumnOptions();
  strict.second_peak_ratio = 0.0;
  r = ExtractOrFail(strict, img.View());
  for (int u = 0; u < 30; ++u) EXPECT_EQ(r.status[u], StripeStatus::kValid) << u;
  for (int u = 30; u < 60; ++u) EXPECT_EQ(r.status[u], StripeStatus::kTwoPeaks) << u;
  EXPECT_EQ(ExpectMatchesReference(img, strict), 30);
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
      EXPECT_NEAR(a.center[u], b.center[u], 0.02) << u;
    }
  }
  // Without the median the hot pixels are stripes (the test above can fail).
  StripeOptions raw = ColumnOptions();
  raw.median_kernel = 1;
  const StripeResult c = ExtractOrFail(raw, hot.View());
  EXPECT_EQ(c.status[75], StripeStatus::kValid);
  // Column 20: the hot pixel (250) outshines the stripe (150 < 0.8 * 250), so it is taken for
  // the stripe; counting every other run, the column is ambiguous.
  EXPECT_EQ(c.status[20], StripeStatus::kValid);
  EXPECT_NEAR(c.center[20], 12.0, 1e-6);
  raw.second_peak_ratio = 0.0;
  EXPECT_EQ(ExtractOrFail(raw, hot.View()).status[20], StripeStatus::kTwoPeaks);
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
