// The height lookup from synthetic calibration frames: a stripe curve v(u) per (line offset,
// stage height), heights recovered between them, and centres far off a curve left out of its
// fit instead of bending it.
#include "insitu/calib/height_lookup.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace insitu::calib {
namespace {

// A smooth synthetic geometry: the stripe of the line at x on the plate at height z lies at
// v = 1000 - 40 z + 3 x + 1e-5 (u - 1200)^2 (a gentle bow) over columns 200..2200.
double V(double x, double z, double u) { return 1000.0 - 40.0 * z + 3.0 * x + 1e-5 * std::pow(u - 1200.0, 2); }

std::vector<HeightObservation> Frames(int outliers_per_frame) {
  std::vector<HeightObservation> obs;
  for (double x = -20; x <= 20; x += 5) {
    for (double z = -10; z <= 10; z += 5) {
      HeightObservation o;
      o.line_x_mm = x;
      o.stage_z_mm = z;
      for (double u = 200; u <= 2200; u += 4) o.centres.emplace_back(u, V(x, z, u));
      for (int k = 0; k < outliers_per_frame; ++k) {
        o.centres[100 + 37 * k].y() += 30.0;  // a few columns of a reflection
      }
      obs.push_back(std::move(o));
    }
  }
  return obs;
}

TEST(HeightLookup, RecoversHeightsBetweenTheCalibratedOnes) {
  HeightLookupSummary s;
  const HeightLookup lookup = HeightLookup::Build(Frames(0), &s);
  ASSERT_TRUE(s.ok) << s.message;
  EXPECT_LT(s.fit_rms_px, 1e-6);
  EXPECT_EQ(s.outliers, 0);
  // v is linear in z here: cubic interpolation between heights is exact to rounding.
  const auto h = lookup.Height(2.5, 900.0, V(2.5, 3.3, 900.0));
  ASSERT_TRUE(h.has_value());
  EXPECT_NEAR(*h, 3.3, 1e-6);
  EXPECT_FALSE(lookup.Height(2.5, 900.0, V(2.5, 40.0, 900.0)).has_value());  // outside
}

// Five centres 30 px off in every frame: without the refit they would bend every curve by
// ~30 px * 5 / 500 points ~ 0.3 px (~0.01 mm); with it the curves are exact again.
TEST(HeightLookup, CentresFarOffTheCurveAreLeftOut) {
  HeightLookupSummary s;
  const HeightLookup lookup = HeightLookup::Build(Frames(5), &s);
  ASSERT_TRUE(s.ok) << s.message;
  EXPECT_EQ(s.outliers, 5 * 9 * 5);
  EXPECT_LT(s.fit_max_px, 1e-6);
  const auto h = lookup.Height(-7.5, 1500.0, V(-7.5, -4.2, 1500.0));
  ASSERT_TRUE(h.has_value());
  EXPECT_NEAR(*h, -4.2, 1e-6);
}

}  // namespace
}  // namespace insitu::calib
