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

// A table of moves (seed 001's kind): every position measured from where the spot was seen at
// the field centre, which has its own measuring error. That row is left out, its error is a
// nuisance common to every move (never named), and the head's distortion about its axis is
// found as from absolute positions.
TEST(Diagnose, ATableOfMovesIsMeasuredFromItsReference) {
  Synth s;
  s.noise_mm = 0.002;
  // 0.19 mm of pincushion and 0.07 mm of radial distortion at the corner, about (2, -1) mm.
  s.effects = {{"rotation", {1e-3}}, {"head_distortion", {1.5e-6, 2e-7, 2.0, -1.0}}};
  FieldData moves = Generate(s);
  int ref = -1;
  for (size_t i = 0; i < moves.points.size(); ++i) {
    if (moves.points[i].cmd.norm() < 1e-9) ref = static_cast<int>(i);
  }
  ASSERT_GE(ref, 0);
  const Eigen::Vector2d seen_at_ref = moves.points[ref].meas;
  for (FieldPoint& p : moves.points) p.meas = p.meas - seen_at_ref;  // moves from the centre
  moves.reference = ref;

  auto d = Diagnose(moves);
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_EQ(d->n_points, 120);  // the reference row is no measurement
  ASSERT_EQ(d->cause.size(), 2u) << d->Summary();
  EXPECT_EQ(d->cause[0], "head_distortion");
  EXPECT_EQ(d->cause[1], "rotation");
  const EffectReport& h = d->effects[0];
  const std::vector<double> truth = {1.5e-6, 2e-7, 2.0, -1.0};
  for (size_t j = 0; j < truth.size(); ++j) {
    SCOPED_TRACE(h.param_names[j]);
    EXPECT_NEAR(h.params[j], truth[j], 4.0 * h.stderrs[j]);
  }
  // Held out: the noise of a move (the point's and the reference's, 2 um per axis each: the
  // reference's is common, so the scatter about the fit is the point's, 2.8 um as a vector).
  EXPECT_LT(d->extended_cv_rms_mm, 1.2 * std::sqrt(2.0) * s.noise_mm);
  // The residuals cover every row of the table, the reference's too, for the plot.
  EXPECT_EQ(d->residual_extended.size(), moves.points.size());
  bool noted = false;
  for (const std::string& note : d->notes)
    noted |= note.find("table of moves") != std::string::npos;
  EXPECT_TRUE(noted);
}

// A grid measured by hand (a ruler, a loupe): 60 um of scatter per axis, no replicates, over a
// small pincushion. Nothing is named, and the report does not call the scatter noise: without
// replicates its noise is not known.
TEST(Diagnose, AHandMeasuredGridWithLargeScatterIsNotCalledNoise) {
  Synth s;
  s.noise_mm = 0.060;
  s.effects = {{"mirror_separation", {2e-7, 0.0, 0.0}}};  // 25 um at the corner
  auto d = Diagnose(Generate(s));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_TRUE(d->cause.empty()) << d->Summary();
  EXPECT_FALSE(d->unexplained) << d->Summary();
  EXPECT_EQ(d->Summary().find("within noise"), std::string::npos) << d->Summary();
  EXPECT_NE(d->Summary().find("no replicates"), std::string::npos) << d->Summary();
  EXPECT_EQ(d->Summary().find("explains"), std::string::npos) << d->Summary();
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
