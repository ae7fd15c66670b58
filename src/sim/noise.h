// Random sources of the simulated camera: photon shot noise, read noise, laser speckle.
// Deterministic: everything derives from the world seed and the frame counter.
#pragma once

#include <cmath>
#include <cstdint>

namespace insitu::sim {

inline uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Uniform in (0, 1) from 53 random bits.
inline double ToUnit(uint64_t x) { return ((x >> 11) + 0.5) * (1.0 / 9007199254740992.0); }

// xoshiro256** stream with Gaussian and Poisson draws.
class NoiseSource {
 public:
  explicit NoiseSource(uint64_t seed) {
    for (uint64_t& s : s_) s = seed = SplitMix64(seed);
  }
  uint64_t Next() {
    const uint64_t result = Rotl(s_[1] * 5, 7) * 9;
    const uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }
  double Uniform() { return ToUnit(Next()); }
  // Standard Gaussian from a 65536-entry inverse-CDF table (tails cut at 4.2 sigma): 8x faster
  // than Box-Muller per pixel of a 5 MP frame (callgrind), and indistinguishable in images.
  double Gaussian() { return GaussianTable()[Next() >> 48]; }
  // Electrons after photon shot noise (Poisson with mean `mean_e`) and Gaussian read noise
  // of variance `read_var_e2`. Poisson is drawn exactly below 20 e-; above, a Gaussian of the
  // same mean and variance (the difference is far below one gray level there).
  double ShotAndRead(double mean_e, double read_var_e2) {
    double e;
    if (mean_e < 20.0) {
      const double limit = std::exp(-mean_e);
      double p = Uniform();
      int k = 0;
      while (p > limit) {
        p *= Uniform();
        ++k;
      }
      e = k;
    } else {
      e = mean_e + std::sqrt(mean_e) * Gaussian();
    }
    return e + std::sqrt(read_var_e2) * Gaussian();
  }

 private:
  static uint64_t Rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  static const float* GaussianTable();
  uint64_t s_[4];
};

// Multiplicative speckle factor of pixel (u, v), mean 1: a fully developed speckle intensity
// |A|^2 (A: complex Gaussian field with correlation length `grain_px`, exponential statistics)
// blended with a uniform part, S = 1 - contrast + contrast * |A|^2 / <|A|^2>, integrated over
// the pixel's area. `contrast` is the standard deviation of S at a point; a pixel's is lower
// where the pixel is not much smaller than a grain.
double SpeckleFactor(int u, int v, double grain_px, double contrast, uint64_t seed);

}  // namespace insitu::sim
