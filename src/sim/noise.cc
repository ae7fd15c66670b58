#include "sim/noise.h"

#include <algorithm>
#include <vector>

namespace insitu::sim {
namespace {

// Two independent standard Gaussians for lattice node (i, j).
void NodeAmplitude(int64_t i, int64_t j, uint64_t seed, double* re, double* im) {
  const uint64_t h1 = SplitMix64(seed ^ SplitMix64(static_cast<uint64_t>(i) * 0x632BE59BD9B4E019ull ^
                                                   static_cast<uint64_t>(j)));
  const uint64_t h2 = SplitMix64(h1);
  const double r = std::sqrt(-2.0 * std::log(ToUnit(h1)));
  const double phi = 2.0 * M_PI * ToUnit(h2);
  *re = r * std::cos(phi);
  *im = r * std::sin(phi);
}

// Inverse of the standard normal CDF (Acklam's rational approximation, |error| < 1.2e-9).
double InverseNormalCdf(double p) {
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                             1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01, -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  const double plow = 0.02425;
  if (p < plow) {
    const double q = std::sqrt(-2 * std::log(p));
    return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
           ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  }
  if (p > 1 - plow) return -InverseNormalCdf(1 - p);
  const double q = p - 0.5, r = q * q;
  return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
         (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
}

}  // namespace

const float* NoiseSource::GaussianTable() {
  static const std::vector<float> table = [] {
    std::vector<float> t(65536);
    for (size_t i = 0; i < t.size(); ++i) {
      t[i] = static_cast<float>(InverseNormalCdf((i + 0.5) / t.size()));
    }
    return t;
  }();
  return table.data();
}

double SpeckleFactor(int u, int v, double grain_px, double contrast, uint64_t seed) {
  // Lattice of random phasors every half grain, smoothed by a Gaussian kernel whose width
  // sets the correlation length; the intensity is normalised by its local expectation so the
  // statistics do not depend on where a point falls in the lattice. The pixel integrates the
  // intensity over its area: the mean of points on an S x S grid inside it, S such that they
  // lie closer than the correlation length (a pixel as large as a grain sees a softer speckle
  // than a point does).
  // The intensity's correlation is exp(-d^2 / (2 sigma^2)) for a kernel of width sigma; a
  // circular pupil's is the Airy pattern [2 J1(v) / v]^2 (Goodman, Speckle Phenomena in
  // Optics, 4.4), whose half width at half maximum is 0.515 lambda N where the grain (its
  // first zero) is 1.22 lambda N: sigma = 0.515 / 1.22 / sqrt(2 ln 2) grain = 0.358 grain
  // gives the same half width.
  const double sigma = 0.358 * grain_px;
  const double spacing = std::max(0.5, sigma);
  const double inv2s2 = 1.0 / (2.0 * sigma * sigma);
  const double reach = 2.0 * sigma;
  const int sub =
      static_cast<int>(std::clamp(std::ceil(1.0 / sigma) + 1.0, 2.0, 4.0));  // <= kMaxSub
  // The nodes any sample reaches, their amplitudes fetched once.
  constexpr int kMaxNodes = 16;
  const int64_t i0 = static_cast<int64_t>(std::floor((u - 0.5 - reach) / spacing));
  const int64_t i1 = static_cast<int64_t>(std::ceil((u + 0.5 + reach) / spacing));
  const int64_t j0 = static_cast<int64_t>(std::floor((v - 0.5 - reach) / spacing));
  const int64_t j1 = static_cast<int64_t>(std::ceil((v + 0.5 + reach) / spacing));
  const int ni = static_cast<int>(std::min<int64_t>(i1 - i0 + 1, kMaxNodes));
  const int nj = static_cast<int>(std::min<int64_t>(j1 - j0 + 1, kMaxNodes));
  double re[kMaxNodes][kMaxNodes], im[kMaxNodes][kMaxNodes];
  for (int b = 0; b < nj; ++b) {
    for (int a = 0; a < ni; ++a) NodeAmplitude(i0 + a, j0 + b, seed, &re[b][a], &im[b][a]);
  }
  // The kernel's weights along one axis: of the n nodes from `origin` for sample k of the
  // pixel at `centre` (the kernel is separable).
  constexpr int kMaxSub = 4;
  const auto weights = [&](int centre, int64_t origin, int n, int k, double* w) {
    const double at = centre - 0.5 + (k + 0.5) / sub;
    for (int i = 0; i < n; ++i) {
      const double d = (origin + i) * spacing - at;
      w[i] = std::abs(d) <= reach ? std::exp(-d * d * inv2s2) : 0.0;
    }
  };
  double wxs[kMaxSub][kMaxNodes];
  for (int sx = 0; sx < sub; ++sx) weights(u, i0, ni, sx, wxs[sx]);
  double intensity = 0.0;
  for (int sy = 0; sy < sub; ++sy) {
    double wy[kMaxNodes];
    weights(v, j0, nj, sy, wy);
    for (int sx = 0; sx < sub; ++sx) {
      const double* wx = wxs[sx];
      double sum_re = 0, sum_im = 0, sum_w2 = 0;
      for (int b = 0; b < nj; ++b) {
        if (wy[b] == 0.0) continue;
        for (int a = 0; a < ni; ++a) {
          const double wgt = wy[b] * wx[a];
          sum_re += wgt * re[b][a];
          sum_im += wgt * im[b][a];
          sum_w2 += wgt * wgt;
        }
      }
      // No node within reach: grains far below the sample spacing, which the pixel averages
      // to their mean.
      intensity += sum_w2 > 0 ? (sum_re * sum_re + sum_im * sum_im) / (2.0 * sum_w2) : 1.0;
    }
  }
  intensity /= sub * sub;
  return std::max(0.0, 1.0 - contrast + contrast * intensity);
}

}  // namespace insitu::sim
