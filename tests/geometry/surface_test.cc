// The measured surface as a height field: heights and normals from nearby cloud points, and
// no invented height where nothing was measured or where the neighbours straddle an edge.
#include "insitu/geometry/surface.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace insitu::geometry {
namespace {

// A scan-like cloud: lines every 0.2 mm in x, points every 0.08 mm along y, of z = f(x, y),
// with Gaussian height noise.
Cloud Scan(double (*f)(double, double), double noise_mm, double x0, double x1) {
  Cloud c;
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, noise_mm);
  int line = 0;
  for (double x = x0; x <= x1 + 1e-9; x += 0.2, ++line) {
    for (double y = -10; y <= 10; y += 0.08) {
      CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(x, y, f(x, y) + (noise_mm > 0 ? n(rng) : 0.0));
      p.line = line;
      c.push_back(p);
    }
  }
  return c;
}

double Tilted(double x, double y) { return 2.0 + 0.1 * x - 0.05 * y; }
double Step(double x, double) { return x < 0 ? 0.0 : 3.0; }

TEST(Surface, HeightAndNormalOfATiltedPlane) {
  auto s = SurfaceModel::Build(Scan(Tilted, 0.0, -5, 5), {});
  ASSERT_TRUE(s.ok());
  const auto at = s->At(1.03, -2.51);
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(at->z_mm, Tilted(1.03, -2.51), 1e-4);  // float storage: ~1e-6 mm
  const Eigen::Vector3d n = Eigen::Vector3d(-0.1, 0.05, 1.0).normalized();
  EXPECT_NEAR(at->normal.dot(n), 1.0, 1e-6);
  // Within 0.3 mm: 2 or 3 lines 0.2 mm apart, each a chord of up to 0.6 mm of 0.08 mm steps.
  EXPECT_GE(at->points, 15);
}

// Noise 0.025 mm per point (the speckle-limited scan), ~19 neighbours: a three-parameter
// plane's height at the query point has ~0.025 * sqrt(1.5 / 19) = 0.007 mm error (the
// neighbours are not centred on the query: leverage ~1.5); bound 0.035 mm (5 sigma) over 200
// queries.
TEST(Surface, AveragesNoise) {
  auto s = SurfaceModel::Build(Scan(Tilted, 0.025, -5, 5), {});
  ASSERT_TRUE(s.ok());
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-4, 4);
  for (int i = 0; i < 200; ++i) {
    const double x = u(rng), y = u(rng);
    const auto at = s->At(x, y);
    ASSERT_TRUE(at.has_value());
    EXPECT_NEAR(at->z_mm, Tilted(x, y), 0.035);
  }
}

TEST(Surface, NoHeightWhereNothingWasMeasuredOrAcrossAnEdge) {
  auto s = SurfaceModel::Build(Scan(Step, 0.0, -5, 5), {});
  ASSERT_TRUE(s.ok());
  SurfaceMiss miss;
  EXPECT_FALSE(s->At(8.0, 0.0, &miss).has_value());  // beyond the scan
  EXPECT_EQ(miss, SurfaceMiss::kNoPoints);
  EXPECT_FALSE(s->At(0.0, 0.0, &miss).has_value());  // on the step edge
  EXPECT_EQ(miss, SurfaceMiss::kEdge);
  const auto top = s->At(1.0, 0.0, &miss);
  ASSERT_TRUE(top.has_value());
  EXPECT_EQ(miss, SurfaceMiss::kNone);
  EXPECT_NEAR(top->z_mm, 3.0, 1e-6);
  EXPECT_FALSE(SurfaceModel::Build({}, {}).ok());
}

// Neighbours all on one scan line (lines wider apart than the radius): the height comes from
// that line, the slope across it is taken as 0, never fitted to the line's rounding noise.
TEST(Surface, OneLineOfNeighboursGivesThatLinesHeight) {
  Cloud c;
  for (double x : {-1.0, 0.0, 1.0}) {
    for (double y = -5; y <= 5; y += 0.08) {
      CloudPoint p;
      // Points of one line scatter by ~1 um in x (float storage, the light plane's tilt).
      p.point_in_galvo = Eigen::Vector3f(x + 1e-3 * std::sin(37 * y), y, 2.0 + 0.1 * x);
      c.push_back(p);
    }
  }
  auto s = SurfaceModel::Build(c, {});
  ASSERT_TRUE(s.ok());
  const auto at = s->At(0.08, 1.0);  // 0.08 mm beside the line x = 0
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(at->z_mm, 2.0, 1e-3);
}

}  // namespace
}  // namespace insitu::geometry
