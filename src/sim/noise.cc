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
  // statistics do not depend on where the pixel falls in the lattice.
  const double spacing = std::max(0.5, 0.5 * grain_px);
  const double sigma = 0.5 * grain_px;
  const double inv2s2 = 1.0 / (2.0 * sigma * sigma);
  const double reach = 2.0 * sigma;
  const double x = u / spacing, y = v / spacing;
  const int64_t i0 = static_cast<int64_t>(std::floor((u - reach) / spacing));
  const int64_t i1 = static_cast<int64_t>(std::ceil((u + reach) / spacing));
  const int64_t j0 = static_cast<int64_t>(std::floor((v - reach) / spacing));
  const int64_t j1 = static_cast<int64_t>(std::ceil((v + reach) / spacing));
  double sum_re = 0, sum_im = 0, sum_w2 = 0;
  for (int64_t j = j0; j <= j1; ++j) {
    for (int64_t i = i0; i <= i1; ++i) {
      const double dx = (i - x) * spacing, dy = (j - y) * spacing;
      const double wgt = std::exp(-(dx * dx + dy * dy) * inv2s2);
      double re, im;
      NodeAmplitude(i, j, seed, &re, &im);
      sum_re += wgt * re;
      sum_im += wgt * im;
      sum_w2 += wgt * wgt;
    }
  }
  const double intensity = (sum_re * sum_re + sum_im * sum_im) / (2.0 * sum_w2);
  return std::max(0.0, 1.0 - contrast + contrast * intensity);
}

}  // namespace insitu::sim
