// The spiral-filled circle target (seed 003 sec. 2.2, Fig. 9) and seed 001's "+": the path
// is checked against the ideal curve (radius grows by one pitch per turn, exact outer radius,
// chord error within tolerance) and, drawn with a line as wide as the pitch, must cover the
// whole disc and nothing outside it.
#include "insitu/pattern/spiral_target.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace insitu::pattern {
namespace {

// Distance from p to the segment [a, b].
double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                       const Eigen::Vector2d& b) {
  const Eigen::Vector2d d = b - a;
  const double len2 = d.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(d) / len2, 0.0, 1.0) : 0.0;
  return (a + t * d - p).norm();
}

// Index of the first point of the closing circle: the spiral reaches r_out only at its end,
// so it is the first point at r_out.
size_t SpiralEnd(const std::vector<Eigen::Vector2d>& path, double r_out) {
  for (size_t i = 0; i < path.size(); ++i) {
    if (std::abs(path[i].norm() - r_out) < 1e-12) return i;
  }
  return path.size();
}

TEST(SpiralTarget, RadiusGrowsByOnePitchPerTurnAndEndsOnTheExactOuterCircle) {
  SpiralTargetOptions o;  // 2.5 mm, 35 um pitch, 1 um chord error
  auto path = SpiralTargetPath(o);
  ASSERT_TRUE(path.ok()) << path.status().ToString();
  const double r_out = SpiralOuterPathRadius(o);
  EXPECT_DOUBLE_EQ(r_out, 0.5 * (2.5 - 0.035));
  EXPECT_EQ(path->front(), Eigen::Vector2d(0, 0));
  const size_t end = SpiralEnd(*path, r_out);
  ASSERT_LT(end, path->size());

  // Along the spiral, with the polar angle unwrapped, r = pitch * theta / (2 pi): the radius
  // grows by exactly one pitch per turn. Points are on the ideal curve, so only rounding
  // separates them from it.
  double theta = 0.0, prev = 0.0;
  for (size_t i = 1; i <= end; ++i) {
    const Eigen::Vector2d& p = (*path)[i];
    const double angle = std::atan2(p.y(), p.x());
    double step = angle - prev;
    step -= 2.0 * M_PI * std::round(step / (2.0 * M_PI));
    ASSERT_GT(step, 0.0) << "the spiral turns counter-clockwise, point " << i;
    ASSERT_LT(step, 0.5 * M_PI + 1e-12) << "at most a quarter turn per chord, point " << i;
    theta += step;
    prev = angle;
    ASSERT_NEAR(p.norm(), o.pitch_mm * theta / (2.0 * M_PI), 1e-12) << "point " << i;
  }
  // Turns: the disc's radius over the pitch.
  EXPECT_NEAR(theta / (2.0 * M_PI), r_out / o.pitch_mm, 1e-9);

  // The closing circle: every point at r_out, one full turn, back where the spiral arrived.
  double turn = 0.0;
  for (size_t i = end + 1; i < path->size(); ++i) {
    EXPECT_NEAR((*path)[i].norm(), r_out, 1e-12);
    const Eigen::Vector2d& a = (*path)[i - 1];
    const Eigen::Vector2d& b = (*path)[i];
    turn += std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
  }
  EXPECT_NEAR(turn, 2.0 * M_PI, 1e-9);
  EXPECT_EQ(path->back(), (*path)[end]);
  for (const Eigen::Vector2d& p : *path) EXPECT_LE(p.norm(), r_out + 1e-12);
}

// The chord error, measured against the ideal curve sampled 200 times per chord: the largest
// distance of the curve from the polyline must stay within the tolerance, and not be far
// below it either (the step is matched to the curvature, not needlessly fine).
TEST(SpiralTarget, ChordErrorWithinTolerance) {
  for (const double tol : {0.001, 0.0002, 0.005}) {
    SpiralTargetOptions o;
    o.diameter_mm = 2.0;
    o.pitch_mm = 0.04;
    o.chord_tolerance_mm = tol;
    auto path = SpiralTargetPath(o);
    ASSERT_TRUE(path.ok()) << path.status().ToString();
    const double a = o.pitch_mm / (2.0 * M_PI);
    const double r_out = SpiralOuterPathRadius(o);
    const size_t end = SpiralEnd(*path, r_out);
    double worst = 0.0, theta0 = 0.0;
    for (size_t i = 1; i < path->size(); ++i) {
      const Eigen::Vector2d& p0 = (*path)[i - 1];
      const Eigen::Vector2d& p1 = (*path)[i];
      // The ideal curve between the two points: the spiral before `end`, then the circle.
      double step = std::atan2(p1.y(), p1.x()) - std::atan2(p0.y(), p0.x());
      step -= 2.0 * M_PI * std::round(step / (2.0 * M_PI));
      if (i == 1) step = p1.norm() / a;  // from the centre, where the angle is undefined
      for (int k = 1; k < 200; ++k) {
        const double th = theta0 + step * k / 200.0;
        const double r = i <= end ? a * th : r_out;
        worst = std::max(
            worst, SegmentDistance(Eigen::Vector2d(r * std::cos(th), r * std::sin(th)), p0, p1));
      }
      theta0 += step;
    }
    EXPECT_LE(worst, tol * (1 + 1e-9)) << "tolerance " << tol;
    EXPECT_GE(worst, 0.5 * tol) << "tolerance " << tol;
  }
}

// Drawn with a line as wide as the pitch (seed 003: spacing = line width), the spiral covers
// the disc. Rasterised at 2.5 um: every cell centre within the disc's radius R = diameter / 2
// is within pitch / 2 of the path, allowing the chord tolerance (a chord lies up to `tol`
// inside the curve); nothing beyond R + tol is. The covered area then equals pi R^2 to the
// cells along the rim: 2 pi R * 2.5 um / pi R^2 = 0.4 % at R = 1.25 mm.
TEST(SpiralTarget, LineAsWideAsThePitchFillsTheDisc) {
  SpiralTargetOptions o;
  o.chord_tolerance_mm = 0.0005;
  auto path = SpiralTargetPath(o);
  ASSERT_TRUE(path.ok()) << path.status().ToString();
  const double cell = 0.0025;
  const double big_r = 0.5 * o.diameter_mm;
  const double reach = 0.5 * o.pitch_mm + o.chord_tolerance_mm;
  const int n = static_cast<int>(std::ceil((big_r + 2 * reach) / cell));
  const int side = 2 * n + 1;
  std::vector<char> covered(static_cast<size_t>(side) * side, 0);
  const auto centre_of = [&](int i) { return (i - n) * cell; };
  for (size_t s = 1; s < path->size(); ++s) {
    const Eigen::Vector2d& a = (*path)[s - 1];
    const Eigen::Vector2d& b = (*path)[s];
    const int i0 =
        std::max(0, static_cast<int>(std::floor((std::min(a.x(), b.x()) - reach) / cell)) + n);
    const int i1 = std::min(
        side - 1, static_cast<int>(std::ceil((std::max(a.x(), b.x()) + reach) / cell)) + n);
    const int j0 =
        std::max(0, static_cast<int>(std::floor((std::min(a.y(), b.y()) - reach) / cell)) + n);
    const int j1 = std::min(
        side - 1, static_cast<int>(std::ceil((std::max(a.y(), b.y()) + reach) / cell)) + n);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        char& c = covered[static_cast<size_t>(j) * side + i];
        if (!c && SegmentDistance({centre_of(i), centre_of(j)}, a, b) <= reach) c = 1;
      }
    }
  }
  int holes = 0, outside = 0;
  double area = 0.0;
  for (int j = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i) {
      const double r = std::hypot(centre_of(i), centre_of(j));
      const bool c = covered[static_cast<size_t>(j) * side + i];
      holes += r <= big_r && !c;
      outside += r > big_r + o.chord_tolerance_mm && c;
      area += c ? cell * cell : 0.0;
    }
  }
  EXPECT_EQ(holes, 0);
  EXPECT_EQ(outside, 0);
  EXPECT_NEAR(area / (M_PI * big_r * big_r), 1.0, 0.004);
}

TEST(SpiralTarget, RefusesBadOptions) {
  SpiralTargetOptions o;
  o.pitch_mm = 0;
  EXPECT_EQ(SpiralTargetPath(o).status().code(), StatusCode::kInvalidArgument);
  o = {};
  o.diameter_mm = 0.05;  // less than two 35 um lines
  EXPECT_EQ(SpiralTargetPath(o).status().code(), StatusCode::kInvalidArgument);
  o = {};
  o.chord_tolerance_mm = 0.02;  // more than a quarter pitch
  EXPECT_EQ(SpiralTargetPath(o).status().code(), StatusCode::kInvalidArgument);
  o = {};
  o.chord_tolerance_mm = 1e-12;  // would need billions of points
  auto r = SpiralTargetPath(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("points"), std::string::npos) << r.status().message();
}

TEST(CrossTarget, BarsOfParallelStrokesSpanLengthAndWidth) {
  CrossTargetOptions o;  // 3 mm x 0.12 mm bars of 35 um lines: 4 strokes each
  auto strokes = CrossTargetStrokes(o);
  ASSERT_TRUE(strokes.ok()) << strokes.status().ToString();
  ASSERT_EQ(strokes->size(), 8u);
  for (int bar = 0; bar < 2; ++bar) {
    double lo = 1e9, hi = -1e9, prev = -1e9;
    for (int k = 0; k < 4; ++k) {
      const Segment2& s = (*strokes)[bar * 4 + k];
      const int along = bar == 0 ? 0 : 1, across = 1 - along;
      EXPECT_DOUBLE_EQ(s.a[across], s.b[across]);
      // Line ends are round: the marked bar spans the stroke plus half a line at each end.
      EXPECT_NEAR(std::abs(s.b[along] - s.a[along]) + o.line_width_mm, o.length_mm, 1e-12);
      EXPECT_NEAR(s.a[along] + s.b[along], 0.0, 1e-12);
      // Alternate directions, spacing no more than a line width (no gap).
      if (k > 0) {
        const Segment2& p = (*strokes)[bar * 4 + k - 1];
        EXPECT_LT((s.b[along] - s.a[along]) * (p.b[along] - p.a[along]), 0.0);
        EXPECT_LE(s.a[across] - prev, o.line_width_mm + 1e-12);
      }
      prev = s.a[across];
      lo = std::min(lo, s.a[across]);
      hi = std::max(hi, s.a[across]);
    }
    EXPECT_NEAR(hi - lo + o.line_width_mm, o.bar_width_mm, 1e-12);
    EXPECT_NEAR(hi + lo, 0.0, 1e-12);
  }
  // A bar one line wide is a single stroke through the centre.
  o.bar_width_mm = o.line_width_mm;
  strokes = CrossTargetStrokes(o);
  ASSERT_TRUE(strokes.ok());
  ASSERT_EQ(strokes->size(), 2u);
  EXPECT_DOUBLE_EQ((*strokes)[0].a.y(), 0.0);
  o.bar_width_mm = 0.01;
  EXPECT_EQ(CrossTargetStrokes(o).status().code(), StatusCode::kInvalidArgument);
  o = {};
  o.length_mm = 0.1;
  EXPECT_EQ(CrossTargetStrokes(o).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::pattern
