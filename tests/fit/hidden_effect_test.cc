// Hidden-effect trials: generated galvo field data with an effect drawn at random (a different
// seeded draw per trial: grid size, field size, noise, magnitude, centre, direction), and the
// diagnosis must name it. Also two-effect mixtures, noise alone, and an effect outside the
// library (a periodic ripple of the field) that must come out as unexplained with no library
// effect claimed. Every data set carries all optional columns (focus z, time, velocity) so the
// effects that need them are always candidates, and the time order is shuffled against
// position, as when points are measured in a random order.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "insitu/fit/diagnose.h"
#include "insitu/fit/effects.h"

namespace insitu::fit {
namespace {

struct Trial {
  FieldData data;
  double noise_rms_mm = 0.0;  // vector rms of the noise
};

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

// Parameters of an effect with a random shape (centre, direction, sign) and unit-ish magnitude;
// `magnitude` lists which parameters scale the size of the effect.
std::vector<double> RandomShape(const std::string& name, double half, std::mt19937_64& rng,
                                std::vector<int>* magnitude) {
  std::normal_distribution<double> g(0.0, 1.0);
  if (name == "offset") return *magnitude = {0, 1}, std::vector<double>{g(rng), g(rng)};
  if (name == "scale") return *magnitude = {0, 1}, std::vector<double>{g(rng), g(rng)};
  if (name == "rotation") return *magnitude = {0}, std::vector<double>{g(rng)};
  if (name == "skew") return *magnitude = {0}, std::vector<double>{g(rng)};
  if (name == "mirror_separation" || name == "lens_radial") {
    *magnitude = {0};
    return {g(rng) > 0 ? 1.0 : -1.0, Uniform(rng, -0.3, 0.3) * half,
            Uniform(rng, -0.3, 0.3) * half};
  }
  if (name == "perspective") return *magnitude = {0, 1}, std::vector<double>{g(rng), g(rng)};
  if (name == "thermal_drift")
    return *magnitude = {0, 1, 2}, std::vector<double>{g(rng), g(rng), g(rng) / half};
  if (name == "tracking_lag") return *magnitude = {0}, std::vector<double>{1.0};
  if (name == "focus_scale") return *magnitude = {0}, std::vector<double>{g(rng) > 0 ? 1.0 : -1.0};
  ADD_FAILURE() << "no shape for " << name;
  return {};
}

// Displacement of every point by one effect.
std::vector<Eigen::Vector2d> Displacement(const FieldData& d, const Effect& e,
                                          const std::vector<double>& params) {
  std::vector<Eigen::Vector2d> out;
  for (const FieldPoint& p : d.points) {
    Eigen::Vector2d uv = p.cmd;
    e.Apply(p, params.data(), &uv);
    out.push_back(uv - p.cmd);
  }
  return out;
}

double Rms(const std::vector<Eigen::Vector2d>& v) {
  double s = 0.0;
  for (const auto& x : v) s += x.squaredNorm();
  return std::sqrt(s / v.size());
}

// A data set with `effects` (library names) hidden in it, each at an rms of 5..30 times the
// noise (or log-uniform in [lo, hi] times it), and optionally a ripple outside the library.
Trial MakeTrial(uint64_t seed, const std::vector<std::string>& effects, bool ripple,
                double lo = 0.0, double hi = 0.0) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 12345);
  std::normal_distribution<double> g(0.0, 1.0);
  const int grid = static_cast<int>(Uniform(rng, 6, 15));  // 6..14 per side
  const double half = Uniform(rng, 10.0, 60.0);            // field +-10..60 mm
  const double sigma = Uniform(rng, 0.001, 0.008);         // per axis, mm
  Trial t;
  t.noise_rms_mm = std::sqrt(2.0) * sigma;
  FieldData& d = t.data;
  d.origin = "<trial " + std::to_string(seed) + ">";
  d.has_z = d.has_t = d.has_v = true;
  std::vector<int> order(grid * grid);
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::shuffle(order.begin(), order.end(), rng);
  for (int j = 0; j < grid; ++j) {
    for (int i = 0; i < grid; ++i) {
      FieldPoint p;
      p.cmd = {-half + 2 * half * i / (grid - 1), -half + 2 * half * j / (grid - 1)};
      p.z_cmd_mm = Uniform(rng, -10.0, 10.0);
      p.t_s = 2.0 * order[j * grid + i];  // measured in a shuffled order, 2 s apart
      const double a = Uniform(rng, 0, 2 * M_PI), speed = Uniform(rng, 200.0, 2000.0);
      p.v_mm_s = speed * Eigen::Vector2d(std::cos(a), std::sin(a));
      p.meas = p.cmd;
      d.points.push_back(p);
    }
  }
  // Each effect scaled to its drawn rms (twice: rotation and perspective are slightly
  // non-linear in their magnitude).
  std::vector<std::unique_ptr<Effect>> lib;
  std::vector<std::vector<double>> params;
  for (const std::string& name : effects) {
    lib.push_back(MakeEffect(name));
    std::vector<int> mag;
    std::vector<double> q = RandomShape(name, half, rng, &mag);
    const double times =
        hi > 0 ? std::exp(Uniform(rng, std::log(lo), std::log(hi))) : Uniform(rng, 5.0, 30.0);
    const double target = times * t.noise_rms_mm;
    for (int it = 0; it < 2; ++it) {
      const double r = Rms(Displacement(d, *lib.back(), q));
      for (int k : mag) q[k] *= target / r;
    }
    params.push_back(q);
  }
  for (FieldPoint& p : d.points) {
    Eigen::Vector2d uv = p.cmd;
    for (int stage = 0; stage <= 2; ++stage) {
      for (size_t k = 0; k < lib.size(); ++k) {
        if (lib[k]->stage() == stage) lib[k]->Apply(p, params[k].data(), &uv);
      }
    }
    p.meas = uv;
  }
  if (ripple) {
    // A periodic error of the field (a galvo encoder's, say) in a random direction, at 5..30
    // times the noise: 1..3 periods across the field, but at least 4 grid spacings per period
    // (sampled finer than that, a ripple aliases into noise that no test can tell apart).
    const double max_cycles = std::max(1.0, std::min(3.0, (grid - 1) / 4.0));
    const double a = Uniform(rng, 0, 2 * M_PI), period = 2 * half / Uniform(rng, 1.0, max_cycles);
    const double phase = Uniform(rng, 0, 2 * M_PI), dir = Uniform(rng, 0, 2 * M_PI);
    std::vector<Eigen::Vector2d> w;
    for (const FieldPoint& p : d.points) {
      const double s =
          std::sin(2 * M_PI * (p.cmd.x() * std::cos(a) + p.cmd.y() * std::sin(a)) / period + phase);
      w.push_back(s * Eigen::Vector2d(std::cos(dir), std::sin(dir)));
    }
    const double k = Uniform(rng, 5.0, 30.0) * t.noise_rms_mm / Rms(w);
    for (size_t i = 0; i < d.points.size(); ++i) d.points[i].meas += k * w[i];
  }
  for (FieldPoint& p : d.points) p.meas += sigma * Eigen::Vector2d(g(rng), g(rng));
  return t;
}

constexpr int kTrials = 50;

bool Named(const Diagnosis& d, const std::string& name) {
  return std::find(d.cause.begin(), d.cause.end(), name) != d.cause.end();
}

class SingleEffect : public ::testing::TestWithParam<std::string> {};

TEST_P(SingleEffect, IsNamedFirst) {
  int first = 0;
  std::string misses;
  for (int k = 0; k < kTrials; ++k) {
    const Trial t = MakeTrial(1000 + k, {GetParam()}, false);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    const bool ok = !d->cause.empty() && d->cause.front() == GetParam();
    first += ok;
    if (!ok && misses.size() < 600)
      misses += "\n  trial " + std::to_string(k) + ": " + d->Summary();
  }
  std::printf("%s named first in %d of %d trials\n", GetParam().c_str(), first, kTrials);
  EXPECT_GE(first, 0.95 * kTrials) << misses;  // the bound: >= 95 %
}

INSTANTIATE_TEST_SUITE_P(Library, SingleEffect,
                         ::testing::Values("offset", "scale", "rotation", "skew",
                                           "mirror_separation", "lens_radial", "perspective",
                                           "thermal_drift", "tracking_lag", "focus_scale"));

// Each effect alone over the whole range a field shows it at: from 3 to 1000 times the noise
// (a 10 um ripple on a coaxial field to a 2 mm pincushion on a 300 mm lens), either sign and
// any shape RandomShape draws. Named first in >= 9 of 10 (the bar).
TEST_P(SingleEffect, IsNamedFirstAtAnyMagnitude) {
  int first = 0;
  std::string misses;
  constexpr int kWide = 10;
  for (int k = 0; k < kWide; ++k) {
    const Trial t = MakeTrial(5000 + k, {GetParam()}, false, 3.0, 1000.0);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    const bool ok = !d->cause.empty() && d->cause.front() == GetParam();
    first += ok;
    if (!ok) misses += "\n  trial " + std::to_string(k) + ": " + d->Summary();
  }
  std::printf("%s named first in %d of %d trials at 3..1000 x the noise\n", GetParam().c_str(),
              first, kWide);
  EXPECT_GE(first, 9) << misses;
}

// An offset and a skew together, each 5..30 times the noise: both named and nothing else (a
// pincushion with its centre at the field's edge holds a constant and a shear of x, and once
// took their place as the first cause).
TEST(HiddenEffects, AnOffsetAndASkewAreNamedNotAPincushion) {
  int right = 0;
  std::string misses;
  for (int k = 0; k < 10; ++k) {
    const Trial t = MakeTrial(6000 + k, {"offset", "skew"}, false);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    const bool ok = d->cause.size() == 2 && Named(*d, "offset") && Named(*d, "skew");
    right += ok;
    if (!ok) misses += "\n  trial " + std::to_string(k) + ": " + d->Summary();
  }
  std::printf("offset + skew: both and only they named in %d of 10\n", right);
  EXPECT_GE(right, 9) << misses;
}

TEST(HiddenEffects, BothEffectsOfAMixtureAreNamed) {
  const std::vector<std::string> names{
      "offset",      "scale",       "rotation",      "skew",         "mirror_separation",
      "lens_radial", "perspective", "thermal_drift", "tracking_lag", "focus_scale"};
  int both = 0;
  std::string misses;
  std::mt19937_64 pick(7);
  for (int k = 0; k < kTrials; ++k) {
    const size_t a = pick() % names.size();
    size_t b = pick() % (names.size() - 1);
    if (b >= a) ++b;
    const Trial t = MakeTrial(2000 + k, {names[a], names[b]}, false);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    const bool ok = Named(*d, names[a]) && Named(*d, names[b]);
    both += ok;
    if (!ok && misses.size() < 800) {
      misses += "\n  trial " + std::to_string(k) + " (" + names[a] + " + " + names[b] +
                "): " + d->Summary();
    }
  }
  std::printf("mixtures: both named in %d of %d trials\n", both, kTrials);
  EXPECT_GE(both, 0.90 * kTrials) << misses;  // >= 90 %
  if (std::getenv("INSITU_SHOW_MISSES")) std::printf("%s\n", misses.c_str());
}

TEST(HiddenEffects, NoiseAloneNamesNothing) {
  int empty = 0, unexplained = 0;
  std::string misses;
  for (int k = 0; k < kTrials; ++k) {
    const Trial t = MakeTrial(3000 + k, {}, false);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    empty += d->cause.empty();
    unexplained += d->unexplained;
    if (!d->cause.empty() && misses.size() < 600)
      misses += "\n  trial " + std::to_string(k) + ": " + d->Summary();
  }
  std::printf("noise only: empty cause in %d of %d trials, unexplained in %d\n", empty, kTrials,
              unexplained);
  EXPECT_GE(empty, 0.95 * kTrials) << misses;  // >= 95 %
}

TEST(HiddenEffects, AnEffectOutsideTheLibraryIsUnexplainedNotPinned) {
  int unexplained = 0, unclaimed = 0;
  std::string misses;
  for (int k = 0; k < kTrials; ++k) {
    const Trial t = MakeTrial(4000 + k, {}, true);
    auto d = Diagnose(t.data);
    ASSERT_TRUE(d.ok()) << d.status().ToString();
    unexplained += d->unexplained;
    unclaimed += d->cause.empty();
    if ((!d->unexplained || !d->cause.empty()) && misses.size() < 800) {
      misses += "\n  trial " + std::to_string(k) + ": " + d->Summary();
    }
  }
  std::printf("ripple: unexplained in %d of %d trials, no library effect claimed in %d\n",
              unexplained, kTrials, unclaimed);
  EXPECT_GE(unexplained, 0.90 * kTrials) << misses;  // >= 90 %
  EXPECT_GE(unclaimed, 0.90 * kTrials) << misses;    // >= 90 %
}

}  // namespace
}  // namespace insitu::fit
