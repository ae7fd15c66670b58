// The diagnosis on generated field data: a hidden library effect is named, the extended model
// predicts held-out points to the noise, noise alone names nothing, and an effect outside the
// library is reported as unexplained rather than pinned on the nearest library effect.
#include "insitu/fit/diagnose.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "fit/field_synth.h"

namespace insitu::fit {
namespace {

using testing::Generate;
using testing::Synth;

TEST(Diagnose, NamesAHiddenPincushionAndMeasuresTheGain) {
  Synth s;
  s.noise_mm = 0.002;
  // kappa = 2e-6 /mm^2: 0.25 mm at the field corner; its centre off the commanded origin.
  s.effects = {{"mirror_separation", {2e-6, 7.0, -4.0}}};
  auto d = Diagnose(Generate(s));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  ASSERT_FALSE(d->cause.empty());
  EXPECT_EQ(d->cause.front(), "mirror_separation");
  // Held-out rms of the extended model: the noise (2 um per axis, 2.8 um as a vector) plus
  // the parameters' estimation error (~3 params over 121 points: a few percent).
  EXPECT_LT(d->extended_cv_rms_mm, 1.2 * std::sqrt(2.0) * s.noise_mm);
  EXPECT_GT(d->gain, 10.0);
  EXPECT_FALSE(d->unexplained);
  std::printf("%s\n", d->Summary().c_str());
}

TEST(Diagnose, NoiseAloneNamesNothing) {
  Synth s;
  s.replicates = 2;  // a noise estimate from replicates
  auto d = Diagnose(Generate(s));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_TRUE(d->cause.empty());
  EXPECT_FALSE(d->unexplained);
  // The replicate noise: sqrt(2) * 2 um, known to ~10 % from 121 pairs.
  EXPECT_NEAR(d->noise_mm, std::sqrt(2.0) * s.noise_mm, 0.15 * std::sqrt(2.0) * s.noise_mm);
}

TEST(Diagnose, AnEffectOutsideTheLibraryIsUnexplained) {
  Synth s;
  // A ripple of the field (e.g. a galvo encoder's periodic error): 30 um, 40 mm period in x.
  s.extra = [](const Eigen::Vector2d& c) {
    return Eigen::Vector2d(0.03 * std::sin(2 * M_PI * c.x() / 40.0), 0.0);
  };
  auto d = Diagnose(Generate(s));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_TRUE(d->unexplained) << d->Summary();
  EXPECT_FALSE(d->unexplained_where.empty());
  std::printf("%s\n", d->Summary().c_str());
}

TEST(Diagnose, ReplicatesTestTheFitAgainstTheirScatter) {
  Synth s;
  s.replicates = 2;
  // A library effect alone: the extended model fits to the replicate scatter.
  s.effects = {{"lens_radial", {3e-7, -5.0, 4.0}}};
  auto explained = Diagnose(Generate(s));
  ASSERT_TRUE(explained.ok());
  EXPECT_EQ(explained->unexplained_test, "lack_of_fit");
  ASSERT_FALSE(explained->cause.empty());
  EXPECT_EQ(explained->cause.front(), "lens_radial");
  EXPECT_FALSE(explained->unexplained) << explained->Summary();
  // Plus a ripple no library effect has: the residual stays well above the scatter.
  s.extra = [](const Eigen::Vector2d& c) {
    return Eigen::Vector2d(0.0, 0.02 * std::sin(2 * M_PI * c.y() / 50.0));
  };
  auto left = Diagnose(Generate(s));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(left->unexplained_test, "lack_of_fit");
  EXPECT_TRUE(left->unexplained) << left->Summary();
  EXPECT_LT(left->unexplained_p, 1e-6);
}

TEST(Diagnose, TooFewPositionsAndBadOptionsAreRefused) {
  FieldData d;
  d.origin = "tiny.csv";
  for (int i = 0; i < 2; ++i) {
    FieldPoint p;
    p.cmd = p.meas = Eigen::Vector2d(i, 0);
    d.points.push_back(p);
  }
  EXPECT_EQ(Diagnose(d).status().code(), StatusCode::kFailedPrecondition);
  DiagnoseOptions o;
  o.alpha = 2.0;
  EXPECT_EQ(Diagnose(d, o).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::fit
