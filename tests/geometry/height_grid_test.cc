// The measured surface on a grid: heights and normals where points surround the node, agreeing
// with the analytic surface and with SurfaceModel, and no height at holes, beyond the scan or
// across an edge.
#include "insitu/geometry/height_grid.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "insitu/geometry/surface.h"

namespace insitu::geometry {
namespace {

// The scan of these tests: lines every 0.1 mm in x, points every 0.05 mm along y. With the
// default options (cell 0.05 mm, half-width h = 0.3 mm) a window holds 6 lines x 12 points = 72.
constexpr double kLine = 0.1;
constexpr double kStep = 0.05;
constexpr double kNoise = 0.01;  // mm, per point
constexpr double kH = 0.3;       // window half-width of the default options

template <typename F>
Cloud Scan(F f, double noise_mm, double x0, double x1, double y0, double y1, unsigned seed = 7) {
  Cloud c;
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise_mm > 0 ? noise_mm : 1.0);
  const int lines = static_cast<int>(std::lround((x1 - x0) / kLine));
  const int steps = static_cast<int>(std::lround((y1 - y0) / kStep));
  for (int l = 0; l <= lines; ++l) {
    const double x = x0 + l * kLine;
    for (int s = 0; s <= steps; ++s) {
      const double y = y0 + s * kStep;
      CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(x, y, f(x, y) + (noise_mm > 0 ? n(rng) : 0.0));
      p.line = l;
      c.push_back(p);
    }
  }
  return c;
}

double Tilted(double x, double y) { return 2.0 + 0.1 * x - 0.05 * y; }

// A cylindrical crown, axis along y, radius 20 mm, top at 11.5 mm (the arc part's height).
constexpr double kR = 20.0;
double Arc(double x, double) { return 11.5 - kR + std::sqrt(kR * kR - x * x); }
// Its curvature as a height field, |z''| = R^2 / (R^2 - x^2)^(3/2), and normal.
double ArcCurvature(double x) { return kR * kR / std::pow(kR * kR - x * x, 1.5); }
Eigen::Vector3d ArcNormal(double x) {
  return Eigen::Vector3d(x, 0, std::sqrt(kR * kR - x * x)) / kR;
}

// Noise: a node's height is the mean of its window's points shifted along the fitted slope by
// the centroid's offset from the node. Inside the scan that offset is at most half a line
// spacing, 0.05 mm, in x (against a spread of 6 lines of 0.029 mm^2) and 0.025 mm in y (spread
// 0.03 mm^2): leverage 1 + 0.05^2 / 0.029 + 0.025^2 / 0.03 < 1.12, so the height's standard
// deviation is below 1.06 sigma / sqrt(points); a bilinear blend of four nodes is no worse than
// its worst node. Bound: 5 of those. (At a border or a hole's rim the centroid can sit far from
// the node: fewer points, more leverage; those cases are checked without noise below.)
double NoiseBound(int points) { return 5.0 * 1.06 * kNoise / std::sqrt(points); }

// Curvature: the plane through the window's points of z = k x^2 / 2 (x from the node) is off
// at the node by k/2 (E[x^2] - m cov(x, x^2) / var(x)), m the centroid's offset; over the
// window's lines that is at most k * 0.02 mm^2 (7 lines at -0.3 .. 0.3 mm, when float rounding
// lets the line on the window's far boundary in; 6 lines: k * 0.0134 mm^2), below k h^2 / 4
// (h = 0.3 mm). Bilinear interpolation between nodes adds at most k cell^2 / 8.
double CurvatureBound(double k) { return k * kH * kH / 4.0 + k * 0.05 * 0.05 / 8.0; }

// Float storage of the cloud: ~1e-6 mm at 12 mm.
constexpr double kFloat = 1e-5;

TEST(HeightGrid, TiltedPlaneExactWithoutNoise) {
  auto grid = HeightGrid::Build(Scan(Tilted, 0.0, -5, 5, -5, 5), {});
  ASSERT_TRUE(grid.ok()) << grid.status().ToString();
  EXPECT_DOUBLE_EQ(grid->window_half_width_mm(), kH);
  const Eigen::Vector3d n = Eigen::Vector3d(-0.1, 0.05, 1.0).normalized();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-4.5, 4.5);
  for (int q = 0; q < 500; ++q) {
    const double x = u(rng), y = u(rng);
    SurfaceMiss miss;
    const auto s = grid->Sample(x, y, &miss);
    ASSERT_TRUE(s.has_value()) << x << ", " << y;
    EXPECT_EQ(miss, SurfaceMiss::kNone);
    EXPECT_NEAR(s->z_mm, Tilted(x, y), kFloat);
    EXPECT_NEAR(s->normal.dot(n), 1.0, 1e-9);
    // 6 lines x 12 points; here lines and points fall on cell boundaries, so float rounding
    // puts the outermost on either side: 5 to 7 lines of 11 to 13 points.
    EXPECT_GE(s->points, 5 * 11);
    EXPECT_LT(s->residual_mm, kFloat);
  }
}

// Far from the galvo origin and high above it: the moments are summed relative to the grid's
// centre and the cloud's mean height, so nothing cancels more than over the part itself. Float
// storage at 150 mm: ~1e-5 mm of x, times the slope 0.1.
TEST(HeightGrid, FarFromTheOriginAsExact) {
  const Eigen::Vector2d shift(150.0, -80.0);
  const auto far = [&](double x, double y) { return 40.0 + Tilted(x - shift.x(), y - shift.y()); };
  auto grid = HeightGrid::Build(
      Scan(far, 0.0, shift.x() - 5, shift.x() + 5, shift.y() - 5, shift.y() + 5), {});
  ASSERT_TRUE(grid.ok());
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-4.5, 4.5);
  for (int q = 0; q < 200; ++q) {
    const double x = shift.x() + u(rng), y = shift.y() + u(rng);
    const auto s = grid->Sample(x, y);
    ASSERT_TRUE(s.has_value());
    EXPECT_NEAR(s->z_mm, far(x, y), 2 * kFloat);
    EXPECT_LT(s->residual_mm, 2 * kFloat);
  }
}

TEST(HeightGrid, PlanesWithNoiseWithinTheDerivedBound) {
  for (auto f :
       {+[](double, double) { return 5.0; }, +[](double x, double y) { return Tilted(x, y); }}) {
    auto grid = HeightGrid::Build(Scan(f, kNoise, -5, 5, -5, 5), {});
    ASSERT_TRUE(grid.ok());
    std::mt19937 rng(13);
    std::uniform_real_distribution<double> u(-4.5, 4.5);
    double worst = 0.0;
    for (int q = 0; q < 500; ++q) {
      const double x = u(rng), y = u(rng);
      const auto s = grid->Sample(x, y);
      ASSERT_TRUE(s.has_value());
      EXPECT_NEAR(s->z_mm, f(x, y), NoiseBound(s->points));  // ~6e-3 mm for 72 points
      worst = std::max(worst, std::abs(s->z_mm - f(x, y)) / NoiseBound(s->points));
      // The rms of n >= 55 residuals of noise sigma is sigma sqrt((n - 3) / n) with a relative
      // spread of 1 / sqrt(2 n) < 0.1; 5 of those.
      EXPECT_NEAR(s->residual_mm, kNoise, 0.5 * kNoise);
    }
    // The bound is 5 sigma, so the worst of 500 queries sits at 2 to 4 sigma: a bound that is
    // far too loose would show here.
    EXPECT_GT(worst, 0.3);
  }
}

TEST(HeightGrid, CylinderArcMatchesTheSurface) {
  for (double noise : {0.0, kNoise}) {
    auto grid = HeightGrid::Build(Scan(Arc, noise, -13, 13, -5, 5), {});
    ASSERT_TRUE(grid.ok());
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> ux(-12, 12), uy(-4.5, 4.5);
    for (int q = 0; q < 500; ++q) {
      const double x = ux(rng), y = uy(rng);
      const auto s = grid->Sample(x, y);
      ASSERT_TRUE(s.has_value()) << x << ", " << y;
      // Up to k = 0.098 / mm at |x| = 12: 2.2e-3 mm of curvature, plus ~6e-3 mm of noise.
      const double bound =
          CurvatureBound(ArcCurvature(x)) + (noise > 0 ? NoiseBound(s->points) : 0.0) + kFloat;
      EXPECT_NEAR(s->z_mm, Arc(x, y), bound) << x << ", " << y;
      if (noise == 0) {
        // The fitted slope is the surface's at the window's centroid, up to half a line spacing
        // from the node: off by at most k * 0.05 rad.
        const double angle = std::acos(std::min(1.0, s->normal.dot(ArcNormal(x))));
        EXPECT_LT(angle, ArcCurvature(x) * 0.5 * kLine + 1e-5) << x;
      }
    }
  }
}

// SurfaceModel fits the same plane to a disc of radius 0.3 mm (~56 points here) instead of a
// square of half-width 0.3 mm (72 points): the curvature biases are k r^2 / 8 against up to
// k h^2 / 4, same sign, so they differ by less than k h^2 / 4; the noise errors by less than the
// sum of both noise bounds (less in fact: the windows share most points).
TEST(HeightGrid, AgreesWithSurfaceModel) {
  for (double noise : {0.0, kNoise}) {
    const Cloud cloud = Scan(Arc, noise, -13, 13, -5, 5);
    auto grid = HeightGrid::Build(cloud, {});
    auto model = SurfaceModel::Build(cloud, {});
    ASSERT_TRUE(grid.ok());
    ASSERT_TRUE(model.ok());
    std::mt19937 rng(19);
    std::uniform_real_distribution<double> ux(-12, 12), uy(-4.5, 4.5);
    for (int q = 0; q < 300; ++q) {
      const double x = ux(rng), y = uy(rng);
      const auto g = grid->Sample(x, y);
      const auto m = model->At(x, y);
      ASSERT_TRUE(g.has_value());
      ASSERT_TRUE(m.has_value());
      double bound = ArcCurvature(x) * kH * kH / 4.0 + kFloat;
      if (noise > 0) bound += NoiseBound(g->points) + NoiseBound(m->points);
      EXPECT_NEAR(g->z_mm, m->z_mm, bound) << x << ", " << y;
    }
  }
}

// Without noise: a valid height at the rim, however lopsided its window, must be the plane's
// exactly (a slope dropped for too little spread would show as a wrong height).
TEST(HeightGrid, NoHeightInAHoleOrBeyondTheScan) {
  Cloud full = Scan(Tilted, 0.0, -5, 5, -5, 5);
  Cloud cloud;
  for (const CloudPoint& p : full) {
    if (p.point_in_galvo.head<2>().norm() > 1.0) cloud.push_back(p);  // a hole of radius 1 mm
  }
  auto grid = HeightGrid::Build(cloud, {});
  ASSERT_TRUE(grid.ok());
  SurfaceMiss miss;
  // Within 1 - sqrt(2) h = 0.58 mm of the hole's centre a node's whole window is in the hole.
  for (double r : {0.0, 0.25, 0.5}) {
    for (int a = 0; a < 8; ++a) {
      const double x = r * std::cos(a * M_PI / 4), y = r * std::sin(a * M_PI / 4);
      EXPECT_FALSE(grid->Sample(x, y, &miss).has_value()) << x << ", " << y;
      EXPECT_EQ(miss, SurfaceMiss::kNoPoints);
    }
  }
  // Across the scan's border (the last line at x = 5, the last points at y = +-5): heights up
  // to the outermost node with points on its far side, never beyond the points.
  for (double t = 4.0; t <= 6.0; t += 0.001) {
    for (const Eigen::Vector2d& q :
         {Eigen::Vector2d(t, 0.3), Eigen::Vector2d(-t, 0.3), Eigen::Vector2d(0.3, t),
          Eigen::Vector2d(0.3, -t), Eigen::Vector2d(t, t)}) {
      const auto s = grid->Sample(q.x(), q.y(), &miss);
      if (t > 5.0 + 1e-6) {
        EXPECT_FALSE(s.has_value()) << q.transpose();
        EXPECT_EQ(miss, SurfaceMiss::kNoPoints);
      }
      if (t <= 5.0 - kLine) {
        EXPECT_TRUE(s.has_value()) << q.transpose();  // not eaten away
      }
      if (s) {
        EXPECT_NEAR(s->z_mm, Tilted(q.x(), q.y()), kFloat);
      }
    }
  }
  // Where the hole's rim leaves a height, it is the plane's, not a guess.
  int rim = 0;
  for (int a = 0; a < 64; ++a) {
    for (double r = 0.6; r <= 1.4; r += 0.02) {
      const double x = r * std::cos(a * M_PI / 32), y = r * std::sin(a * M_PI / 32);
      const auto s = grid->Sample(x, y);
      if (s) {
        EXPECT_NEAR(s->z_mm, Tilted(x, y), kFloat) << x << ", " << y;
        ++rim;
      }
    }
  }
  EXPECT_GT(rim, 64 * 10);  // of 64 x 41: the rim is not all refused
  EXPECT_FALSE(grid->Sample(NAN, 0.0, &miss).has_value());
  EXPECT_EQ(miss, SurfaceMiss::kNoPoints);
}

// A 1 mm step at x = 0.025, between the lines at x = 0 and 0.1. The windows of the nodes in
// (-0.2, 0.3] hold both lines, so a query in [-0.15, 0.25] has all four nodes straddling the
// step. Such a window holds a fraction p >= 1/7 of its lines on the other level: a plane fit
// leaves rms H sqrt(p (1 - p) (1 - 3 p (1 - p))) >= 0.27 mm, over max_residual_mm = 0.1: an
// edge. In general a window passes only with p <~ (max_residual / H)^2, and its height is then
// off by p H <~ max_residual^2 / H = 0.01 mm.
TEST(HeightGrid, AStepIsAnEdgeNotARamp) {
  constexpr double kStepHeight = 1.0;
  const auto step = [](double x, double) { return x < 0.025 ? 2.0 : 2.0 + kStepHeight; };
  auto grid = HeightGrid::Build(Scan(step, kNoise, -3, 3, -3, 3), {});
  ASSERT_TRUE(grid.ok());
  SurfaceMiss miss;
  for (double x : {-0.15, -0.1, 0.0, 0.025, 0.1, 0.2, 0.25}) {
    EXPECT_FALSE(grid->Sample(x, 0.4, &miss).has_value()) << x;
    EXPECT_EQ(miss, SurfaceMiss::kEdge) << x;
  }
  const double max_residual = HeightGridOptions{}.max_residual_mm;
  int valid = 0;
  for (double x = -1.5; x <= 1.5; x += 0.005) {
    const auto s = grid->Sample(x, 0.4, &miss);
    if (!s) {
      EXPECT_EQ(miss, SurfaceMiss::kEdge) << x;
      continue;
    }
    ++valid;
    const double level = s->z_mm < 2.0 + 0.5 * kStepHeight ? 2.0 : 2.0 + kStepHeight;
    EXPECT_NEAR(s->z_mm, level, max_residual * max_residual / kStepHeight + NoiseBound(s->points))
        << x;
  }
  EXPECT_GT(valid, 400);  // of 601: only the band of about +-h around the step is lost
}

// Points on one diagonal line (scattered ~1 um across it, as float storage and the light
// plane's tilt leave them): every half-window holds points, but they spread in one direction
// only, so the plane takes the slope along the line and none across it (as SurfaceModel), not
// a slope fitted to the scatter. On z = 2 + 0.05 (x + y), whose gradient lies along the line,
// that is exact.
TEST(HeightGrid, OneLineOfPointsGivesItsSlopeAlongIt) {
  Cloud c;
  for (int k = -200; k <= 200; ++k) {
    const double t = 0.02 * k;
    const double x = t + 1e-3 * std::sin(37 * t), y = t - 1e-3 * std::sin(37 * t);
    CloudPoint p;
    p.point_in_galvo = Eigen::Vector3f(x, y, 2.0 + 0.05 * (x + y));
    c.push_back(p);
  }
  auto grid = HeightGrid::Build(c, {});
  ASSERT_TRUE(grid.ok());
  const Eigen::Vector3d n = Eigen::Vector3d(-0.05, -0.05, 1.0).normalized();
  for (double t = -3.0; t <= 3.0; t += 0.013) {
    for (double across : {-0.02, 0.0, 0.02}) {
      const auto s = grid->Sample(t + across, t - across);
      ASSERT_TRUE(s.has_value()) << t << ", " << across;
      EXPECT_NEAR(s->z_mm, 2.0 + 0.1 * t, kFloat) << t << ", " << across;
      // The direction of spread tilts from the line by up to scatter / h = 1e-3 / 0.3, taking
      // that fraction of the gradient (0.07) off the normal: below 2.4e-4 rad.
      EXPECT_LT(std::acos(std::min(1.0, s->normal.dot(n))), 2.4e-4);
    }
  }
}

TEST(HeightGrid, RasterGivesTheSameAnswersAsSample) {
  auto grid = HeightGrid::Build(Scan(Arc, kNoise, -6, 6, -3, 3), {});
  ASSERT_TRUE(grid.ok());
  // Over the border on every side, at a pitch that is no multiple of the cell.
  Raster raster;
  raster.x0_mm = -6.5;
  raster.y0_mm = -3.4;
  raster.pitch_x_mm = 0.0371;
  raster.pitch_y_mm = 0.0523;
  raster.cols = 351;
  raster.rows = 131;
  RasterHeights out;
  ASSERT_TRUE(grid->SampleRaster(raster, &out, true).ok());
  ASSERT_EQ(out.z_mm.size(), 351u * 131u);
  ASSERT_EQ(out.normal.size(), out.z_mm.size());
  int64_t valid = 0;
  for (int r = 0; r < raster.rows; ++r) {
    for (int c = 0; c < raster.cols; ++c) {
      const size_t k = static_cast<size_t>(r) * raster.cols + c;
      SurfaceMiss miss;
      const auto s = grid->Sample(raster.x0_mm + c * raster.pitch_x_mm,
                                  raster.y0_mm + r * raster.pitch_y_mm, &miss);
      ASSERT_EQ(out.miss[k], miss) << r << ", " << c;
      if (!s) {
        EXPECT_TRUE(std::isnan(out.z_mm[k]));
        continue;
      }
      ++valid;
      EXPECT_NEAR(out.z_mm[k], s->z_mm, kFloat);
      EXPECT_NEAR(out.normal[k].cast<double>().dot(s->normal), 1.0, 1e-6);
    }
  }
  EXPECT_EQ(out.valid, valid);
  EXPECT_GT(valid, 351 * 131 / 2);
  EXPECT_LT(valid, 351 * 131);  // the border rows and columns have none
  // Buffers are reused; without normals there are none.
  ASSERT_TRUE(grid->SampleRaster(raster, &out).ok());
  EXPECT_TRUE(out.normal.empty());
  EXPECT_EQ(out.valid, valid);
}

TEST(HeightGrid, BadInputIsRefusedWithTheReason) {
  const Cloud cloud = Scan(Tilted, 0.0, -1, 1, -1, 1);
  EXPECT_EQ(HeightGrid::Build({}, {}).status().code(), StatusCode::kInvalidArgument);
  const auto bad = [&](auto edit) {
    HeightGridOptions o;
    edit(o);
    EXPECT_FALSE(o.Validate().ok());
    const auto g = HeightGrid::Build(cloud, o);
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    return g.status().message();
  };
  EXPECT_NE(bad([](auto& o) { o.cell_mm = 0; }).find("cell_mm"), std::string::npos);
  bad([](auto& o) { o.cell_mm = -0.05; });
  bad([](auto& o) { o.cell_mm = NAN; });
  EXPECT_NE(bad([](auto& o) { o.radius_mm = 0; }).find("radius_mm"), std::string::npos);
  bad([](auto& o) { o.radius_mm = -1; });
  bad([](auto& o) { o.radius_mm = 0.02; });  // under one cell
  bad([](auto& o) { o.min_points = 2; });
  bad([](auto& o) { o.max_residual_mm = 0; });
  bad([](auto& o) { o.max_cells = 0; });

  // Two points a metre apart (a stray point): 20001 x 20001 cells of 0.05 mm.
  Cloud stray = cloud;
  CloudPoint far;
  far.point_in_galvo = Eigen::Vector3f(999, 999, 0);
  stray.push_back(far);
  const auto big = HeightGrid::Build(stray, {});
  ASSERT_FALSE(big.ok());
  EXPECT_EQ(big.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(big.status().message().find("20001 x 20001"), std::string::npos)
      << big.status().message();
  EXPECT_NE(big.status().message().find("max_cells"), std::string::npos);

  Cloud nan_point = cloud;
  nan_point[3].point_in_galvo.z() = NAN;
  const auto n = HeightGrid::Build(nan_point, {});
  EXPECT_EQ(n.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(n.status().message().find("point 3"), std::string::npos);

  auto grid = HeightGrid::Build(cloud, {});
  ASSERT_TRUE(grid.ok());
  RasterHeights out;
  Raster raster;
  raster.rows = raster.cols = 10;
  raster.pitch_x_mm = 0.1;
  EXPECT_EQ(grid->SampleRaster(raster, &out).code(), StatusCode::kInvalidArgument);  // pitch_y 0
  raster.pitch_y_mm = 0.1;
  EXPECT_TRUE(grid->SampleRaster(raster, &out).ok());
  raster.rows = -1;
  EXPECT_EQ(grid->SampleRaster(raster, &out).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::geometry
