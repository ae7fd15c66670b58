// Marks placed on the measured surface: every point at the surface's height, nothing marked
// where nothing was measured, and a pattern off the part refused.
#include "insitu/pattern/mark_plan.h"

#include <cmath>

#include <gtest/gtest.h>

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
  // The scanned 10 mm: heights reach at most 0.1 mm past the outer lines, and the points lie
  // on a 0.2 mm grid from x = -8.
  EXPECT_NEAR(report.marked_length_mm, 10.0, 0.25);
  EXPECT_GT(report.points_without_surface, 20);      // ~3 mm each side at 0.2 mm steps
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
