// Vector patterns from HPGL: coordinates in plotter units (40 per mm), absolute
// and relative, closed shapes, clear errors; hatching of closed shapes by the
// even-odd rule.
#include "insitu/pattern/vector.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace insitu::pattern {
namespace {

double HatchLength(const std::vector<Segment2>& s) {
  double total = 0;
  for (const Segment2& x : s) total += (x.b - x.a).norm();
  return total;
}

TEST(Hpgl, ParsesAbsoluteRelativeAndClosedPaths) {
  // A 10 x 5 mm rectangle (closed) and a relative 2 mm tick; SP and VS carry no
  // geometry.
  auto p =
      ParseHpgl("IN;SP1;VS20;PU0,0;PD400,0,400,200,0,200,0,0;PU;PR40,40;PD0,80;PU;", "test.plt");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 2u);
  EXPECT_TRUE(p->paths[0].closed);
  EXPECT_EQ(p->paths[0].points.size(), 4u);
  EXPECT_NEAR(p->paths[0].points[1].x(), 10.0, 1e-12);
  EXPECT_NEAR(p->paths[0].points[2].y(), 5.0, 1e-12);
  EXPECT_FALSE(p->paths[1].closed);
  EXPECT_NEAR(p->paths[1].points[0].x(), 1.0, 1e-12);  // (0,0) + (40,40) units
  EXPECT_NEAR(p->paths[1].points[1].y(), 3.0, 1e-12);  // + (0, 80)
  EXPECT_EQ(p->ignored_commands, 2);
  EXPECT_EQ(Outline(*p).size(), 4u + 1u);
}

TEST(Hpgl, BadFilesAreNamed) {
  auto bad = ParseHpgl("IN;PD10,1.2.3;", "bad.plt");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_NE(bad.status().message().find("bad.plt: byte 3: PD: '1.2.3' is not a number"),
            std::string::npos)
      << bad.status().message();
  EXPECT_NE(ParseHpgl("PD10,20,30;", "odd.plt").status().message().find("expected pairs"),
            std::string::npos);
  EXPECT_EQ(ParseHpgl("IN;SP1;PU10,10;", "empty.plt").status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ParseHpgl("\x01\x02garbage", "bin.plt").status().code(), StatusCode::kParseError);
  EXPECT_EQ(LoadHpgl("/nonexistent/x.plt").status().code(), StatusCode::kNotFound);
}

// A 10 x 10 mm square with a 4 x 4 mm square hole: the even-odd fill is 84
// mm^2, so hatch lines 0.1 mm apart add up to 840 mm (to within one line at
// each edge: +-2 x 10 mm).
TEST(Hatch, EvenOddFillOfAShapeWithAHole) {
  VectorPattern p;
  p.paths.push_back({{{0, 0}, {10, 0}, {10, 10}, {0, 10}}, true});
  p.paths.push_back({{{3, 3}, {7, 3}, {7, 7}, {3, 7}}, true});
  for (double angle : {0.0, 90.0, 30.0}) {
    auto h = HatchPolygons(p, 0.1, angle);
    ASSERT_TRUE(h.ok());
    EXPECT_NEAR(HatchLength(*h), 840.0, 20.0) << angle;
    for (const Segment2& s : *h) {
      const Eigen::Vector2d mid = 0.5 * (s.a + s.b);
      const bool in_hole = mid.x() > 3 && mid.x() < 7 && mid.y() > 3 && mid.y() < 7;
      EXPECT_FALSE(in_hole) << angle;
    }
  }
  VectorPattern open;
  open.paths.push_back({{{0, 0}, {1, 1}}, false});
  EXPECT_FALSE(HatchPolygons(open, 0.1, 0).ok());
  EXPECT_FALSE(HatchPolygons(p, 0.0, 0).ok());
}

}  // namespace
}  // namespace insitu::pattern

namespace insitu::pattern {
namespace {

TEST(TravelOrder, NearestEntriesShortenTheJumps) {
  // Ten open strokes laid out in a row but listed in a scrambled order, every
  // other one drawn right to left, plus a closed square whose nearest corner is
  // not its first.
  VectorPattern p;
  const int order[10] = {7, 2, 9, 0, 5, 3, 8, 1, 6, 4};
  for (int k : order) {
    Polyline s;
    s.points = {{k * 2.0, 0.0}, {k * 2.0, 1.0}};
    if (k % 2) std::reverse(s.points.begin(), s.points.end());
    p.paths.push_back(s);
  }
  Polyline square;
  square.closed = true;
  square.points = {{30.0, 5.0}, {31.0, 5.0}, {31.0, 6.0}, {30.0, 6.0}};
  p.paths.push_back(square);
  double before = 0.0;
  const double after = OrderForTravel(&p, {0.0, 0.0}, &before);
  // Boustrophedon through the row: 9 jumps of 2 mm (each stroke entered at the
  // end where the last one left; the tenth ends at (18, 0)), then to the
  // square's nearest corner (30, 5).
  const double expected = 9 * 2.0 + std::hypot(12.0, 5.0);
  EXPECT_NEAR(after, expected, 1e-9);
  EXPECT_GT(before, 2.0 * after);
  ASSERT_EQ(p.paths.size(), 11u);
  EXPECT_TRUE(p.paths.back().closed);
  EXPECT_EQ(p.paths.back().points.front(), Eigen::Vector2d(30.0, 5.0));
  // Nothing lost: the same strokes, each intact.
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(p.paths[i].points.size(), 2u);
    EXPECT_NEAR(std::abs(p.paths[i].points[1].y() - p.paths[i].points[0].y()), 1.0, 1e-12);
  }
}

}  // namespace
}  // namespace insitu::pattern
