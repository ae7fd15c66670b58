// DXF input: entities to paths in mm, arcs and bulges flattened within tolerance, splines by
// de Boor, units from $INSUNITS, and errors that name the line.
#include <cmath>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "insitu/pattern/vector.h"

namespace insitu::pattern {
namespace {

// A DXF from (code, value) pairs.
std::string Dxf(std::initializer_list<std::pair<int, std::string>> entities, int insunits = 4) {
  std::ostringstream s;
  s << "0\nSECTION\n2\nHEADER\n9\n$INSUNITS\n70\n" << insunits << "\n0\nENDSEC\n";
  s << "0\nSECTION\n2\nENTITIES\n";
  for (const auto& [code, value] : entities) s << code << "\n" << value << "\n";
  s << "0\nENDSEC\n0\nEOF\n";
  return s.str();
}

double Area(const VectorPattern& p, double spacing) {
  auto h = HatchPolygons(p, spacing, 0.0);
  EXPECT_TRUE(h.ok()) << h.status().ToString();
  double total = 0;
  for (const Segment2& s : *h) total += (s.b - s.a).norm();
  return total * spacing;
}

TEST(Dxf, LinesCirclesArcs) {
  auto p = ParseDxf(Dxf({{0, "LINE"}, {8, "0"}, {10, "0"}, {20, "0"}, {11, "10"}, {21, "0"},
                         {0, "CIRCLE"}, {10, "20"}, {20, "0"}, {40, "5"},
                         {0, "ARC"}, {10, "0"}, {20, "0"}, {40, "2"}, {50, "0"}, {51, "90"},
                         {0, "TEXT"}, {1, "label"}}),
                    "a.dxf");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 3u);
  EXPECT_NEAR(p->paths[0].points[1].x(), 10.0, 1e-12);
  EXPECT_TRUE(p->paths[1].closed);
  for (const auto& q : p->paths[1].points) EXPECT_NEAR((q - Eigen::Vector2d(20, 0)).norm(), 5.0, 1e-9);
  const auto& arc = p->paths[2].points;
  EXPECT_NEAR(arc.front().x(), 2.0, 1e-12);
  EXPECT_NEAR(arc.back().y(), 2.0, 1e-12);  // counterclockwise from 0 to 90 degrees
  EXPECT_EQ(p->ignored_commands, 1);
  EXPECT_NEAR(Area(*p, 0.02), M_PI * 25.0, 0.3);
}

// A counterclockwise 10 mm square whose right side is a bulge of 1 (a half circle outward):
// 100 + 12.5 pi mm^2.
TEST(Dxf, LwPolylineWithBulge) {
  auto p = ParseDxf(Dxf({{0, "LWPOLYLINE"}, {90, "4"}, {70, "1"},
                         {10, "0"}, {20, "0"}, {10, "10"}, {20, "0"}, {42, "1"},
                         {10, "10"}, {20, "10"}, {10, "0"}, {20, "10"}}),
                    "b.dxf");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 1u);
  EXPECT_TRUE(p->paths[0].closed);
  double max_x = 0;
  for (const auto& q : p->paths[0].points) max_x = std::max(max_x, q.x());
  EXPECT_NEAR(max_x, 15.0, 0.005);
  EXPECT_NEAR(Area(*p, 0.05), 100.0 + 12.5 * M_PI, 1.5);
}

TEST(Dxf, UnitsAndSplines) {
  auto inch = ParseDxf(Dxf({{0, "LINE"}, {10, "0"}, {20, "0"}, {11, "1"}, {21, "0"}}, 1), "in.dxf");
  ASSERT_TRUE(inch.ok());
  EXPECT_NEAR(inch->paths[0].points[1].x(), 25.4, 1e-12);
  // Clamped cubic with 4 control points: the cubic Bezier; at t = 1/2 it is
  // (P0 + 3 P1 + 3 P2 + P3) / 8 = (5, 7.5) for (0,0), (0,10), (10,10), (10,0).
  auto s = ParseDxf(Dxf({{0, "SPLINE"}, {70, "8"}, {71, "3"}, {72, "8"}, {73, "4"},
                         {40, "0"}, {40, "0"}, {40, "0"}, {40, "0"},
                         {40, "1"}, {40, "1"}, {40, "1"}, {40, "1"},
                         {10, "0"}, {20, "0"}, {10, "0"}, {20, "10"},
                         {10, "10"}, {20, "10"}, {10, "10"}, {20, "0"}}),
                    "s.dxf");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  const auto& pts = s->paths[0].points;
  EXPECT_NEAR(pts.front().norm(), 0.0, 1e-9);
  EXPECT_NEAR((pts.back() - Eigen::Vector2d(10, 0)).norm(), 0.0, 1e-6);
  double best = 1e9;
  for (const auto& q : pts) best = std::min(best, (q - Eigen::Vector2d(5, 7.5)).norm());
  EXPECT_LT(best, 0.2);  // sampled every ~0.2 mm along the curve
}

TEST(Dxf, BadFilesAreNamed) {
  auto bad = ParseDxf(Dxf({{0, "LINE"}, {10, "zero"}, {20, "0"}, {11, "1"}, {21, "0"}}), "n.dxf");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_NE(bad.status().message().find("LINE group 10: 'zero' is not a number"), std::string::npos)
      << bad.status().message();
  EXPECT_NE(ParseDxf(Dxf({{0, "CIRCLE"}, {10, "0"}, {20, "0"}}), "c.dxf").status().message().find(
                "CIRCLE without group 40"),
            std::string::npos);
  EXPECT_NE(ParseDxf("0\nSECTION\n2\nHEADER\n0\nENDSEC\n0\nEOF\n", "e.dxf").status().message().find(
                "no ENTITIES section"),
            std::string::npos);
  EXPECT_NE(ParseDxf("0\nSECTION\n2\n", "t.dxf").status().message().find("without its value"),
            std::string::npos);
  EXPECT_EQ(ParseDxf(Dxf({{0, "TEXT"}, {1, "x"}}), "x.dxf").status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadDxf("/nonexistent.dxf").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace insitu::pattern
