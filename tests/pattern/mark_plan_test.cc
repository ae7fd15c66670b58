// Marks placed on the measured surface: every point at the surface's height,
// nothing marked where nothing was measured, and a pattern off the part
// refused.
#include "insitu/pattern/mark_plan.h"

#include <gtest/gtest.h>

#include <cmath>

namespace insitu::pattern {
namespace {

double Plane(double x, double y) { return 3.0 + 0.05 * x + 0.02 * y; }

// A scan of the plane over x in [-5, 5] (lines every 0.2 mm), y in [-10, 10].
geometry::Cloud Scan() {
  geometry::Cloud c;
  int line = 0;
  for (double x = -5; x <= 5 + 1e-9; x += 0.2, ++line) {
    for (double y = -10; y <= 10; y += 0.08) {
      geometry::CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(x, y, Plane(x, y));
      p.line = line;
      c.push_back(p);
    }
  }
  return c;
}

TEST(MarkPlan, MarksFollowTheSurfaceAndStopWhereNothingWasMeasured) {
  auto surface = geometry::SurfaceModel::Build(Scan(), {});
  ASSERT_TRUE(surface.ok());
  MarkSettings settings;
  MarkPlanReport report;
  // One line from x = -8 to 8 at y = 1: only |x| <= 5 lies on the scan.
  auto list = PlanMarking({{{-8.0, 1.0}, {8.0, 1.0}}}, *surface, settings, &report);
  ASSERT_TRUE(list.ok()) << list.status().ToString();
  int marks = 0, jumps = 0;
  for (const ListCommand& c : *list) {
    if (c.op != ListOp::kMarkAbs && c.op != ListOp::kJumpAbs) continue;
    (c.op == ListOp::kMarkAbs ? marks : jumps)++;
    EXPECT_LE(std::abs(c.p.x()), 5.1);
    EXPECT_NEAR(c.p.z(), Plane(c.p.x(), c.p.y()), 1e-4);  // float cloud storage
  }
  EXPECT_EQ(jumps, 1);
  EXPECT_EQ(marks, report.marks);
  // The scanned 10 mm: heights reach at most 0.1 mm past the outer lines, and
  // the points lie on a 0.2 mm grid from x = -8.
  EXPECT_NEAR(report.marked_length_mm, 10.0, 0.25);
  EXPECT_GT(report.points_without_surface,
            20);  // ~3 mm each side at 0.2 mm steps
  for (const Eigen::Vector2d& p : report.unmarked_mm) EXPECT_GT(std::abs(p.x()), 5.0);
  EXPECT_NEAR(report.z_min_mm, Plane(-5.0, 1.0), 0.01);

  // Emitted through the head's limits as any list.
  EXPECT_TRUE(Emit(*list, HeadFormat{}).ok());
}

TEST(MarkPlan, PatternOffThePartIsRefused) {
  auto surface = geometry::SurfaceModel::Build(Scan(), {});
  ASSERT_TRUE(surface.ok());
  MarkPlanReport report;
  auto list = PlanMarking({{{20.0, 0.0}, {25.0, 0.0}}}, *surface, MarkSettings{}, &report);
  ASSERT_FALSE(list.ok());
  EXPECT_EQ(list.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(list.status().message().find("place it on the scanned part"), std::string::npos);
  MarkSettings bad;
  bad.max_step_mm = 0;
  EXPECT_FALSE(PlanMarking({{{0, 0}, {1, 0}}}, *surface, bad, nullptr).ok());
}

}  // namespace
}  // namespace insitu::pattern

namespace insitu::pattern {
namespace {

TEST(MarkPlan, AConnectedPathIsOneMarkSequence) {
  auto surface = geometry::SurfaceModel::Build(Scan(), {});
  ASSERT_TRUE(surface.ok());
  // A square outline as four segments, each starting where the last ended: one
  // jump, then marks all the way round (the laser never switches off at a
  // corner).
  const std::vector<Segment2> square{
      {{0, 0}, {1, 0}}, {{1, 0}, {1, 1}}, {{1, 1}, {0, 1}}, {{0, 1}, {0, 0}}};
  MarkPlanReport report;
  auto list = PlanMarking(square, *surface, MarkSettings{}, &report);
  ASSERT_TRUE(list.ok());
  int jumps = 0;
  for (const ListCommand& c : *list) jumps += c.op == ListOp::kJumpAbs;
  EXPECT_EQ(jumps, 1);
  EXPECT_NEAR(report.marked_length_mm, 4.0, 1e-9);
}

// A cylinder crown along y, radius 27.8 mm (the simulated arc part's), top at z
// = 11.5.
double Crown(double x) { return 11.5 - 27.8 + std::sqrt(27.8 * 27.8 - x * x); }

geometry::Cloud CrownScan() {
  geometry::Cloud c;
  for (double x = -15; x <= 15 + 1e-9; x += 0.1) {
    for (double y = -3; y <= 3; y += 0.1) {
      geometry::CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(x, y, Crown(x));
      c.push_back(p);
    }
  }
  return c;
}

// Length of a path along the true crown (fine numeric integration of each
// mapped piece).
double ArcLength(const std::vector<Segment2>& segs) {
  double total = 0.0;
  for (const Segment2& s : segs) {
    for (int k = 0; k < 400; ++k) {
      const Eigen::Vector2d a = s.a + (s.b - s.a) * (k / 400.0),
                            b = s.a + (s.b - s.a) * ((k + 1) / 400.0);
      total += std::sqrt((b - a).squaredNorm() + std::pow(Crown(b.x()) - Crown(a.x()), 2));
    }
  }
  return total;
}

TEST(Wrap, KeepsTheLengthOnACurvedSurface) {
  auto surface = geometry::SurfaceModel::Build(CrownScan(), {});
  ASSERT_TRUE(surface.ok());
  // A 20 mm line across the crown, and one along it.
  const std::vector<Segment2> across{{{-10.0, 0.5}, {10.0, 0.5}}};
  const std::vector<Segment2> along{{{1.0, -2.0}, {1.0, 2.0}}};
  auto wrapped = WrapOnSurface(across, {0.0, 0.5}, *surface, 0.2);
  ASSERT_TRUE(wrapped.ok()) << wrapped.status().ToString();
  // Projected straight down the line covers 2 R asin(10 / R) = 20.457 mm of
  // surface (slopes up to 21 deg at x = +-10); wrapped, 20 mm. The surface is
  // an exact cylinder sampled every 0.1 mm, so the local planes' heights are
  // good to ~1e-4 mm and the 0.2 mm chords of R = 27.8 mm sag by 2e-4 mm: the
  // wrapped length is right to ~1e-3 mm.
  EXPECT_NEAR(ArcLength(across), 2 * 27.8 * std::asin(10.0 / 27.8), 1e-3);
  EXPECT_NEAR(ArcLength(*wrapped), 20.0, 2e-3);
  // Along the cylinder's axis nothing changes (the cloud is float: heights
  // carry ~1e-6 mm rounding, the section's length over 2 mm then ~1e-5 mm).
  auto straight = WrapOnSurface(along, {1.0, 0.0}, *surface, 0.2);
  ASSERT_TRUE(straight.ok());
  EXPECT_NEAR(straight->front().a.y(), -2.0, 1e-4);
  EXPECT_NEAR(straight->back().b.y(), 2.0, 1e-4);
  // An anchor off the measured surface is refused.
  EXPECT_FALSE(WrapOnSurface(across, {40.0, 0.0}, *surface, 0.2).ok());
}

}  // namespace
}  // namespace insitu::pattern
