// SVG input: units from width/height over viewBox, y flipped up, shapes, path commands
// (absolute and relative, curves and arcs flattened within tolerance), transforms, and errors
// that name the element.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "insitu/pattern/vector.h"

namespace insitu::pattern {
namespace {

// 1 user unit = 1 mm.
std::string Svg(const std::string& body) {
  return "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"100mm\" height=\"100mm\" "
         "viewBox=\"0 0 100 100\">" + body + "</svg>";
}

double HatchedArea(const VectorPattern& p, double spacing) {
  auto h = HatchPolygons(p, spacing, 0.0);
  EXPECT_TRUE(h.ok()) << h.status().ToString();
  double total = 0;
  for (const Segment2& s : *h) total += (s.b - s.a).norm();
  return total * spacing;
}

TEST(Svg, UnitsFromViewBoxAndYUp) {
  // 200 x 100 user units on 20 x 10 mm: 0.1 mm per unit.
  auto p = ParseSvg("<svg width=\"20mm\" height=\"10mm\" viewBox=\"0 0 200 100\">"
                    "<rect x=\"10\" y=\"10\" width=\"100\" height=\"50\"/></svg>", "t.svg");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 1u);
  const Polyline& r = p->paths[0];
  EXPECT_TRUE(r.closed);
  ASSERT_EQ(r.points.size(), 4u);
  EXPECT_NEAR(r.points[0].x(), 1.0, 1e-12);
  EXPECT_NEAR(r.points[0].y(), -1.0, 1e-12);  // SVG y down -> pattern y up
  EXPECT_NEAR(r.points[2].x(), 11.0, 1e-12);
  EXPECT_NEAR(r.points[2].y(), -6.0, 1e-12);
  EXPECT_NEAR(HatchedArea(*p, 0.05), 50.0, 1.0);  // 10 x 5 mm, +- a line at each edge
}

// Chords within 5 um of a 5 mm circle; the hatched area is pi r^2.
TEST(Svg, CircleFlattenedWithinTolerance) {
  auto p = ParseSvg(Svg("<circle cx=\"50\" cy=\"50\" r=\"5\"/>"), "c.svg");
  ASSERT_TRUE(p.ok());
  const Polyline& c = p->paths[0];
  EXPECT_TRUE(c.closed);
  for (size_t i = 0; i < c.points.size(); ++i) {
    const Eigen::Vector2d a = c.points[i], b = c.points[(i + 1) % c.points.size()];
    EXPECT_NEAR((a - Eigen::Vector2d(50, -50)).norm(), 5.0, 1e-9);
    // Sagitta of the chord: its midpoint's distance inside the circle.
    EXPECT_LT(5.0 - (0.5 * (a + b) - Eigen::Vector2d(50, -50)).norm(), 0.005 + 1e-12);
  }
  EXPECT_NEAR(HatchedArea(*p, 0.02), M_PI * 25.0, 0.3);
}

// A 10 x 10 square with a semicircular bulge (arc, radius 5) on its right side: 100 + 12.5 pi.
TEST(Svg, PathWithArcAndRelativeCommands) {
  auto p = ParseSvg(Svg("<path d=\"M 0 0 h 10 A 5 5 0 0 1 10 10 l -10 0 z\"/>"), "a.svg");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 1u);
  EXPECT_TRUE(p->paths[0].closed);
  double max_x = 0;
  for (const auto& q : p->paths[0].points) max_x = std::max(max_x, q.x());
  EXPECT_NEAR(max_x, 15.0, 0.005);  // the bulge's apex
  EXPECT_NEAR(HatchedArea(*p, 0.05), 100.0 + 12.5 * M_PI, 1.5);
}

// Quadratic M0 0 Q5 10 10 0: y = 2x - 0.2x^2 (user units, y down), every flattened point on
// it to rounding, chords within the tolerance.
TEST(Svg, QuadraticCurveOnItsParabola) {
  auto p = ParseSvg(Svg("<path fill=\"none\" d=\"M0 0 Q5 10 10 0\"/>"), "q.svg");
  ASSERT_TRUE(p.ok());
  const auto& pts = p->paths[0].points;
  ASSERT_GT(pts.size(), 10u);
  for (const auto& q : pts) EXPECT_NEAR(-q.y(), 2 * q.x() - 0.2 * q.x() * q.x(), 1e-9);
  EXPECT_FALSE(p->paths[0].closed);
}

TEST(Svg, NestedTransforms) {
  auto p = ParseSvg(Svg("<g transform=\"translate(10,0)\"><g transform=\"rotate(90)\">"
                        "<line x1=\"0\" y1=\"0\" x2=\"10\" y2=\"0\"/></g></g>"),
                    "t.svg");
  ASSERT_TRUE(p.ok());
  const auto& pts = p->paths[0].points;
  // rotate(90) maps (10, 0) to (0, 10); translate to (10, 10); y flipped: (10, -10).
  EXPECT_NEAR(pts[1].x(), 10.0, 1e-9);
  EXPECT_NEAR(pts[1].y(), -10.0, 1e-9);
  EXPECT_NEAR(pts[0].x(), 10.0, 1e-9);
  EXPECT_NEAR(pts[0].y(), 0.0, 1e-9);
}

TEST(Svg, OutlinesWithoutFillAreNotAreas) {
  auto p = ParseSvg(Svg("<rect fill=\"none\" x=\"0\" y=\"0\" width=\"4\" height=\"4\"/>"), "o.svg");
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(p->paths[0].closed);
  EXPECT_EQ(p->paths[0].points.size(), 5u);  // back to the start
  EXPECT_FALSE(HatchPolygons(*p, 0.1, 0.0).ok());
  EXPECT_EQ(Outline(*p).size(), 4u);
}

// The points attribute is read from the element's own text (the reader once kept a reference to
// a temporary copy of it, and real files with 4-10 pairs were refused). A 30 x 20 triangle and a
// three-segment polyline, as design tools write them (commas, spaces and newlines mixed).
TEST(Svg, PolygonAndPolylinePoints) {
  auto p = ParseSvg(Svg("<polygon points=\"10,10 40,10\n 40,30\"/>"
                        "<polyline fill=\"none\" points=\"0 0, 3 4 3,8 0 8\"/>"),
                    "pp.svg");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 2u);
  EXPECT_TRUE(p->paths[0].closed);
  ASSERT_EQ(p->paths[0].points.size(), 3u);
  EXPECT_NEAR(p->paths[0].points[2].x(), 40.0, 1e-12);
  EXPECT_NEAR(p->paths[0].points[2].y(), -30.0, 1e-12);
  EXPECT_NEAR(HatchedArea(*p, 0.02), 300.0, 3.0);  // 30 x 20 / 2, +- a line along each edge
  EXPECT_FALSE(p->paths[1].closed);
  double length = 0;
  const auto& q = p->paths[1].points;
  for (size_t i = 1; i < q.size(); ++i) length += (q[i] - q[i - 1]).norm();
  EXPECT_NEAR(length, 5.0 + 4.0 + 3.0, 1e-12);
  // A long points list: 10 pairs.
  auto big = ParseSvg(Svg("<polygon points=\"0,0 1,0 2,0 3,0 4,0 4,4 3,4 2,4 1,4 0,4\"/>"), "b.svg");
  ASSERT_TRUE(big.ok()) << big.status().ToString();
  EXPECT_EQ(big->paths[0].points.size(), 10u);
}

TEST(Svg, BadFilesAreNamed) {
  auto xml = ParseSvg("<svg><rect></svg>", "x.svg");
  ASSERT_FALSE(xml.ok());
  EXPECT_EQ(xml.status().code(), StatusCode::kParseError);
  EXPECT_NE(xml.status().message().find("x.svg: not well-formed XML"), std::string::npos);
  auto path = ParseSvg(Svg("<path id=\"logo\" d=\"M 0 0 L 1\"/>"), "p.svg");
  ASSERT_FALSE(path.ok());
  EXPECT_NE(path.status().message().find("<path id=\"logo\">"), std::string::npos)
      << path.status().message();
  EXPECT_NE(path.status().message().find("L needs x y"), std::string::npos);
  EXPECT_FALSE(ParseSvg("<html/>", "h.svg").ok());
  EXPECT_EQ(ParseSvg(Svg("<text>hi</text>"), "e.svg").status().code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(ParseSvg(Svg("<g transform=\"spin(3)\"><line x2=\"1\"/></g>"), "t.svg").ok());
  EXPECT_EQ(LoadSvg("/nonexistent.svg").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace insitu::pattern
