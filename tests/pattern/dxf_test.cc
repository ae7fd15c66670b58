// DXF input: entities to paths in mm, arcs and bulges flattened within tolerance, splines by
// de Boor, units from $INSUNITS, block insertion, OCS, hatch boundaries, chains closed into
// loops, texts, what is skipped and counted, lenient EOF, and errors that name the line.
//
// The fixtures in tests/pattern/data/dxf/ are small hand-made drawings of known geometry (their
// README says what each holds). Areas and lengths are compared within 0.5 %: the flattening
// tolerance of 0.005 mm on the smallest radius used (3 mm) loses at most 1.33 tol / r = 0.22 %
// of a circle's area (an inscribed polygon of chord angle t keeps 1 - t^2 / 6, t^2 = 8 tol / r)
// and less of its length, so an error above 0.5 % is a geometry error, not flattening.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "insitu/pattern/text.h"
#include "insitu/pattern/vector.h"

namespace insitu::pattern {
namespace {

constexpr double kRel = 0.005;

// A DXF from (code, value) pairs.
std::string Dxf(std::initializer_list<std::pair<int, std::string>> entities, int insunits = 4) {
  std::ostringstream s;
  s << "0\nSECTION\n2\nHEADER\n9\n$INSUNITS\n70\n" << insunits << "\n0\nENDSEC\n";
  s << "0\nSECTION\n2\nENTITIES\n";
  for (const auto& [code, value] : entities) s << code << "\n" << value << "\n";
  s << "0\nENDSEC\n0\nEOF\n";
  return s.str();
}

std::string DataPath(const std::string& name) {
  return std::string(INSITU_SOURCE_DIR) + "/tests/pattern/data/dxf/" + name;
}

std::string ReadData(const std::string& name) {
  std::ifstream f(DataPath(name), std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

double Area(const VectorPattern& p, double spacing) {
  auto h = HatchPolygons(p, spacing, 0.0);
  EXPECT_TRUE(h.ok()) << h.status().ToString();
  if (!h.ok()) return 0.0;
  double total = 0;
  for (const Segment2& s : *h) total += (s.b - s.a).norm();
  return total * spacing;
}

// Shoelace area, signed (counterclockwise positive).
double Shoelace(const Polyline& p) {
  double a = 0;
  for (size_t k = 0; k < p.points.size(); ++k) {
    const auto& u = p.points[k];
    const auto& v = p.points[(k + 1) % p.points.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return 0.5 * a;
}

double Length(const Polyline& p) {
  double l = 0;
  for (size_t k = 1; k < p.points.size(); ++k) l += (p.points[k] - p.points[k - 1]).norm();
  if (p.closed) l += (p.points.front() - p.points.back()).norm();
  return l;
}

Eigen::Vector2d Centre(const Polyline& p) {
  Eigen::Vector2d lo = p.points[0], hi = p.points[0];
  for (const auto& q : p.points) lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
  return 0.5 * (lo + hi);
}

struct Extent {
  Eigen::Vector2d lo{1e300, 1e300}, hi{-1e300, -1e300};
};

Extent Extents(const VectorPattern& p) {
  Extent e;
  for (const auto& l : p.paths) {
    for (const auto& q : l.points) e.lo = e.lo.cwiseMin(q), e.hi = e.hi.cwiseMax(q);
  }
  return e;
}

// The paths whose box centre lies in [lo, hi].
std::vector<Polyline> In(const VectorPattern& p, Eigen::Vector2d lo, Eigen::Vector2d hi) {
  std::vector<Polyline> out;
  for (const auto& l : p.paths) {
    const Eigen::Vector2d c = Centre(l);
    if (c.x() >= lo.x() && c.y() >= lo.y() && c.x() <= hi.x() && c.y() <= hi.y()) out.push_back(l);
  }
  return out;
}

VectorPattern Of(std::vector<Polyline> paths) {
  VectorPattern p;
  p.paths = std::move(paths);
  return p;
}

int Count(const std::map<std::string, int>& m, const std::string& k) {
  const auto it = m.find(k);
  return it == m.end() ? 0 : it->second;
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
  for (const auto& q : p->paths[1].points) {
    EXPECT_NEAR((q - Eigen::Vector2d(20, 0)).norm(), 5.0, 1e-9);
  }
  const auto& arc = p->paths[2].points;
  EXPECT_NEAR(arc.front().x(), 2.0, 1e-12);
  EXPECT_NEAR(arc.back().y(), 2.0, 1e-12);  // counterclockwise from 0 to 90 degrees
  // A TEXT without a height cannot be drawn: counted and explained, not dropped silently.
  EXPECT_EQ(Count(p->skipped, "text"), 1);
  EXPECT_FALSE(p->warnings.empty());
  EXPECT_EQ(Count(p->converted, "line"), 1);
  EXPECT_EQ(Count(p->converted, "circle"), 1);
  EXPECT_EQ(Count(p->converted, "arc"), 1);
  EXPECT_EQ(p->units, "mm");
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
  EXPECT_NEAR(Shoelace(p->paths[0]), 100.0 + 12.5 * M_PI, kRel * (100.0 + 12.5 * M_PI));
}

TEST(Dxf, UnitsAndSplines) {
  auto inch = ParseDxf(Dxf({{0, "LINE"}, {10, "0"}, {20, "0"}, {11, "1"}, {21, "0"}}, 1), "in.dxf");
  ASSERT_TRUE(inch.ok());
  EXPECT_NEAR(inch->paths[0].points[1].x(), 25.4, 1e-12);
  EXPECT_EQ(inch->units, "in");
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

// A rational quadratic with weights 1, sqrt(2)/2, 1 on (10,0), (10,10), (0,10) is the exact
// quarter circle of radius 10 (the way CAD stores circles as NURBS); without the weights it
// would bulge inward by up to 10 (1 - 3/4 sqrt 2 ...) ~ 0.6 mm.
TEST(Dxf, RationalSplineIsExact) {
  auto s = ParseDxf(Dxf({{0, "SPLINE"}, {70, "12"}, {71, "2"}, {72, "6"}, {73, "3"},
                         {40, "0"}, {40, "0"}, {40, "0"}, {40, "1"}, {40, "1"}, {40, "1"},
                         {41, "1"}, {41, "0.70710678118654752"}, {41, "1"},
                         {10, "10"}, {20, "0"}, {10, "10"}, {20, "10"}, {10, "0"}, {20, "10"}}),
                    "r.dxf");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  for (const auto& q : s->paths[0].points) EXPECT_NEAR(q.norm(), 10.0, 1e-9);
}

TEST(Dxf, BadFilesAreNamed) {
  auto bad = ParseDxf(Dxf({{0, "LINE"}, {10, "zero"}, {20, "0"}, {11, "1"}, {21, "0"}}), "n.dxf");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_NE(bad.status().message().find("line 18: LINE group 10: 'zero' is not a number"),
            std::string::npos)
      << bad.status().message();
  EXPECT_NE(ParseDxf(Dxf({{0, "CIRCLE"}, {10, "0"}, {20, "0"}}), "c.dxf").status().message().find(
                "CIRCLE without group 40"),
            std::string::npos);
  EXPECT_NE(ParseDxf("0\nSECTION\n2\nHEADER\n0\nENDSEC\n0\nEOF\n", "e.dxf").status().message().find(
                "no ENTITIES section"),
            std::string::npos);
  EXPECT_NE(ParseDxf("0\nSECTION\n2\n", "t.dxf").status().message().find("without its value"),
            std::string::npos);
  // Non-finite numbers are not numbers.
  for (const char* v : {"nan", "inf", "-inf", "1e999"}) {
    auto r = ParseDxf(Dxf({{0, "LINE"}, {10, "0"}, {20, v}, {11, "1"}, {21, "0"}}), "f.dxf");
    EXPECT_EQ(r.status().code(), StatusCode::kParseError) << v;
  }
  // Nothing drawable: invalid_argument, naming what the file held.
  auto points = ParseDxf(Dxf({{0, "POINT"}, {10, "1"}, {20, "1"}}), "x.dxf");
  EXPECT_EQ(points.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(points.status().message().find("point 1"), std::string::npos)
      << points.status().message();
  EXPECT_EQ(LoadDxf("/nonexistent.dxf").status().code(), StatusCode::kNotFound);
}

// blocks_nested_r2000.dxf: block SQ (a 10 mm square, base point at its centre) inserted by
// block PAIR as is and at (30, 0) scaled (2, 0.5) and turned 90 degrees; PAIR inserted at
// (100, 100) mirrored (x scale -1) and turned 30 degrees; SQ as a 3 x 2 array (20 / 15 mm).
TEST(Dxf, NestedInsertScaleRotationMirrorArray) {
  auto p = LoadDxf(DataPath("blocks_nested_r2000.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 8u);
  double area = 0, length = 0;
  for (const auto& l : p->paths) {
    EXPECT_TRUE(l.closed);
    EXPECT_NEAR(std::abs(Shoelace(l)), 100.0, 1e-9);  // scale 2 x 0.5 keeps the area
    area += std::abs(Shoelace(l));
    length += Length(l);
  }
  EXPECT_NEAR(area, 800.0, kRel * 800.0);
  EXPECT_NEAR(length, 40 * 7 + 50, kRel * 330.0);  // the stretched square is 20 x 5
  // PAIR's first square sits on the insertion point; its second, at (30, 0) in the block, is
  // mirrored to (-30, 0) and turned 30 degrees: (100 - 30 cos 30, 100 - 30 sin 30).
  // Unmirrored it would land at (125.98, 115). Its box: the upright 5 x 20 rectangle turned by
  // 30 degrees.
  const Eigen::Vector2d second(100 - 30 * std::cos(M_PI / 6), 100 - 30 * std::sin(M_PI / 6));
  bool found_first = false, found_second = false;
  for (const auto& l : p->paths) {
    if ((Centre(l) - Eigen::Vector2d(100, 100)).norm() < 1e-9) found_first = true;
    const double half_w = 2.5 * std::cos(M_PI / 6) + 10 * std::sin(M_PI / 6);
    if ((Centre(l) - second).norm() < 1e-9) {
      found_second = true;
      Eigen::Vector2d lo = l.points[0], hi = l.points[0];
      for (const auto& q : l.points) lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
      EXPECT_NEAR(hi.x() - lo.x(), 2 * half_w, 1e-9);
      EXPECT_LT(Shoelace(l), 0.0);  // the mirror reverses the winding
    }
  }
  EXPECT_TRUE(found_first);
  EXPECT_TRUE(found_second);
  // The array: centres at (20 c, 200 + 15 r), the block name matched without case.
  EXPECT_EQ(In(*p, {-1, 199}, {41, 216}).size(), 6u);
  const Extent e = Extents(*p);
  EXPECT_NEAR(e.hi.y(), 220.0, 1e-9);
  EXPECT_EQ(Count(p->converted, "insert"), 2 + 2);  // two in ENTITIES, two in PAIR
  EXPECT_EQ(Count(p->converted, "lwpolyline"), 8);
  EXPECT_TRUE(p->skipped.empty());
}

// ocs_mirror_r2000.dxf: ARC (10,0) r 5 from 0 to 90 degrees, CIRCLE (20,5) r 3, a closed
// LWPOLYLINE square (30..40 x 0..10) with a half-circle bulge on its right side, and an INSERT
// at (5,0) of a 10 mm LINE, all with extrusion (0,0,-1): x is mirrored.
TEST(Dxf, OcsMirrorsArcCircleLwpolylineInsert) {
  auto p = LoadDxf(DataPath("ocs_mirror_r2000.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 4u);
  const Polyline& arc = p->paths[0];
  EXPECT_NEAR((arc.points.front() - Eigen::Vector2d(-15, 0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((arc.points.back() - Eigen::Vector2d(-10, 5)).norm(), 0.0, 1e-9);
  EXPECT_NEAR(Length(arc), 2.5 * M_PI, kRel * 2.5 * M_PI);
  for (const auto& q : arc.points) EXPECT_NEAR((q - Eigen::Vector2d(-10, 0)).norm(), 5.0, 1e-9);
  const Polyline& circle = p->paths[1];
  EXPECT_NEAR((Centre(circle) - Eigen::Vector2d(-20, 5)).norm(), 0.0, 0.005);  // chord sag
  EXPECT_NEAR(std::abs(Shoelace(circle)), 9 * M_PI, kRel * 9 * M_PI);
  const Polyline& lw = p->paths[2];
  double lo = 1e9, hi = -1e9;
  for (const auto& q : lw.points) lo = std::min(lo, q.x()), hi = std::max(hi, q.x());
  EXPECT_NEAR(lo, -45.0, 0.005);  // the bulge points away from the square: to -x once mirrored
  EXPECT_NEAR(hi, -30.0, 1e-9);
  EXPECT_NEAR(std::abs(Shoelace(lw)), 100 + 12.5 * M_PI, kRel * (100 + 12.5 * M_PI));
  const Polyline& line = p->paths[3];
  EXPECT_NEAR((line.points.front() - Eigen::Vector2d(-5, 0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((line.points.back() - Eigen::Vector2d(-15, 0)).norm(), 0.0, 1e-9);
}

// ocs_polyline_crlf_r12.dxf: an R12 2D POLYLINE (10 x 5 rectangle at the origin) with
// extrusion (0,0,-1), right-justified group codes and CRLF line ends; no $INSUNITS.
TEST(Dxf, OcsPolylineR12Crlf) {
  // A checkout that normalised line ends would no longer test them.
  ASSERT_NE(ReadData("ocs_polyline_crlf_r12.dxf").find("\r\n"), std::string::npos);
  auto p = LoadDxf(DataPath("ocs_polyline_crlf_r12.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 1u);
  const Extent e = Extents(*p);
  EXPECT_NEAR(e.lo.x(), -10.0, 1e-12);
  EXPECT_NEAR(e.hi.x(), 0.0, 1e-12);
  EXPECT_NEAR(std::abs(Shoelace(p->paths[0])), 50.0, 1e-9);
  EXPECT_EQ(p->units, "unitless (read as mm)");
}

// hatch_r2000.dxf: A polyline loop with a bulge (100 + 12.5 pi), B an edge loop of lines and
// a counterclockwise arc (200 + 12.5 pi; pattern ANSI31), C a quarter disc closed by a
// clockwise arc edge (25 pi), D a full elliptic edge (50 pi), E a square with a circular
// island (400 - 25 pi), F a hatch over a closed LWPOLYLINE of the drawing (100, filled once),
// G a spline edge (Bezier over its chord: 60).
TEST(Dxf, HatchBoundaryLoops) {
  auto p = LoadDxf(DataPath("hatch_r2000.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(Count(p->converted, "hatch"), 7);
  EXPECT_EQ(Count(p->converted, "hatch_loop_on_outline"), 1);
  // Each loop closed, no pattern line drawn: A, B, C, D, E (2), F (1), G.
  ASSERT_EQ(p->paths.size(), 8u);
  for (const auto& l : p->paths) EXPECT_TRUE(l.closed);
  auto area_in = [&](double x0, double x1) {
    const auto loops = In(*p, {x0, -100}, {x1, 100});
    double a = 0;
    for (const auto& l : loops) a += std::abs(Shoelace(l));
    return std::make_pair(loops.size(), a);
  };
  const auto a = area_in(-1, 16), b = area_in(19, 46), c = area_in(59, 71), d = area_in(89, 111);
  EXPECT_EQ(a.first, 1u);
  EXPECT_NEAR(a.second, 100 + 12.5 * M_PI, kRel * (100 + 12.5 * M_PI));
  EXPECT_NEAR(b.second, 200 + 12.5 * M_PI, kRel * (200 + 12.5 * M_PI));
  EXPECT_NEAR(c.second, 25 * M_PI, kRel * 25 * M_PI);
  EXPECT_NEAR(d.second, 50 * M_PI, kRel * 50 * M_PI);
  const auto e = In(*p, {199, -1}, {221, 21});
  ASSERT_EQ(e.size(), 2u);
  const auto f = area_in(299, 311), g = area_in(399, 411);
  EXPECT_EQ(f.first, 1u);
  EXPECT_NEAR(f.second, 100.0, 1e-9);
  EXPECT_NEAR(g.second, 60.0, kRel * 60.0);
  // The quarter disc: its arc runs clockwise from (60, 10) to (70, 0), outside the chord.
  const Extent ec = Extents(Of(In(*p, {59, -1}, {71, 11})));
  EXPECT_NEAR(ec.hi.x(), 70.0, 1e-9);
  EXPECT_NEAR(ec.hi.y(), 10.0, 1e-9);
  // The job's hatch fills all of it by the even-odd rule: the island stays empty and F is
  // filled once. A scan-line area at 0.01 mm spacing is within ~0.1 % here.
  const double expected = (100 + 12.5 * M_PI) + (200 + 12.5 * M_PI) + 25 * M_PI + 50 * M_PI +
                          (400 - 25 * M_PI) + 100 + 60;
  EXPECT_NEAR(Area(*p, 0.01), expected, kRel * expected);
}

// Hatch style 2 ("ignore") fills the external loop whole: the island loop is not an area.
TEST(Dxf, HatchStyleIgnoreFillsTheExternalLoop) {
  auto hatch = [](int style) {
    return Dxf({{0, "HATCH"}, {10, "0"}, {20, "0"}, {30, "0"}, {2, "SOLID"}, {70, "1"},
                {91, "2"},
                {92, "3"}, {72, "0"}, {73, "1"}, {93, "4"}, {10, "0"}, {20, "0"}, {10, "20"},
                {20, "0"}, {10, "20"}, {20, "20"}, {10, "0"}, {20, "20"}, {97, "0"},
                {92, "18"}, {72, "0"}, {73, "1"}, {93, "4"}, {10, "5"}, {20, "5"}, {10, "15"},
                {20, "5"}, {10, "15"}, {20, "15"}, {10, "5"}, {20, "15"}, {97, "0"},
                {75, std::to_string(style)}, {76, "1"}, {98, "0"}});
  };
  auto nested = ParseDxf(hatch(0), "h0.dxf");
  ASSERT_TRUE(nested.ok()) << nested.status().ToString();
  EXPECT_EQ(nested->paths.size(), 2u);
  EXPECT_NEAR(Area(*nested, 0.01), 300.0, kRel * 300.0);
  auto ignore = ParseDxf(hatch(2), "h2.dxf");
  ASSERT_TRUE(ignore.ok()) << ignore.status().ToString();
  EXPECT_EQ(ignore->paths.size(), 1u);
  EXPECT_NEAR(Area(*ignore, 0.01), 400.0, kRel * 400.0);
}

// chain_r12.dxf: a stadium of two LINEs and two ARCs (200 + 25 pi), out of order and one line
// reversed; an open two-line chain; a square that misses closing by 0.01 mm; a square with a
// tail at a corner (the tail stays open, the square closes); an open POLYLINE "U" closed by a
// LINE (50).
TEST(Dxf, ChainsOfLinesAndArcsClose) {
  auto p = LoadDxf(DataPath("chain_r12.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(Count(p->converted, "chained_loop"), 3);
  const auto stadium = In(*p, {-6, -1}, {26, 11});
  ASSERT_EQ(stadium.size(), 1u);
  EXPECT_TRUE(stadium[0].closed);
  EXPECT_NEAR(std::abs(Shoelace(stadium[0])), 200 + 25 * M_PI, kRel * (200 + 25 * M_PI));
  EXPECT_NEAR(Length(stadium[0]), 40 + 10 * M_PI, kRel * (40 + 10 * M_PI));
  const auto open_chain = In(*p, {49, -1}, {61, 11});
  EXPECT_EQ(open_chain.size(), 2u);
  for (const auto& l : open_chain) EXPECT_FALSE(l.closed);
  const auto gap = In(*p, {79, -1}, {91, 11});
  EXPECT_EQ(gap.size(), 4u);
  for (const auto& l : gap) EXPECT_FALSE(l.closed);
  const auto tail = In(*p, {119, -1}, {141, 21});
  ASSERT_EQ(tail.size(), 2u);
  EXPECT_TRUE(tail[0].closed);
  EXPECT_NEAR(std::abs(Shoelace(tail[0])), 100.0, 1e-9);
  EXPECT_FALSE(tail[1].closed);
  const auto u = In(*p, {149, -1}, {161, 6});
  ASSERT_EQ(u.size(), 1u);
  EXPECT_TRUE(u[0].closed);
  EXPECT_NEAR(std::abs(Shoelace(u[0])), 50.0, 1e-9);
  // Hatchable now: the stadium, the square with the tail and the rectangle, nothing else.
  EXPECT_NEAR(Area(*p, 0.01), 350 + 25 * M_PI, kRel * (350 + 25 * M_PI));
}

// mesh_r12.dxf: a polyface mesh (flag 64, whose face record has 0,0 coordinates) and a 2 x 2
// polygon mesh (flag 16), then a LINE from (100,100) to (110,100).
TEST(Dxf, MeshesAreSkippedAndCounted) {
  auto p = LoadDxf(DataPath("mesh_r12.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(Count(p->skipped, "polyface_mesh"), 1);
  EXPECT_EQ(Count(p->skipped, "polygon_mesh"), 1);
  ASSERT_EQ(p->paths.size(), 1u);
  const Extent e = Extents(*p);
  EXPECT_NEAR(e.lo.x(), 100.0, 1e-12);  // no line to the origin from a face record
  EXPECT_NEAR(e.lo.y(), 100.0, 1e-12);
}

TEST(Dxf, LenientEndOfFile) {
  auto junk = LoadDxf(DataPath("junk_after_eof_r12.dxf"));
  ASSERT_TRUE(junk.ok()) << junk.status().ToString();
  EXPECT_EQ(junk->paths.size(), 1u);
  EXPECT_TRUE(junk->warnings.empty());
  auto missing = LoadDxf(DataPath("missing_eof_r12.dxf"));
  ASSERT_TRUE(missing.ok()) << missing.status().ToString();
  EXPECT_EQ(missing->paths.size(), 1u);
  ASSERT_EQ(missing->warnings.size(), 1u);
  EXPECT_NE(missing->warnings[0].find("no EOF"), std::string::npos);
  // Cut inside ENTITIES: refused, naming the last line.
  auto cut = LoadDxf(DataPath("truncated_r2000.dxf"));
  ASSERT_FALSE(cut.ok());
  EXPECT_EQ(cut.status().code(), StatusCode::kParseError);
  EXPECT_NE(cut.status().message().find("ends inside its ENTITIES section"), std::string::npos)
      << cut.status().message();
  EXPECT_NE(cut.status().message().find("line 54"), std::string::npos) << cut.status().message();
  // Junk after a complete ENTITIES section, with no EOF: ignored with a warning.
  const std::string text = ReadData("missing_eof_r12.dxf") + "garbage\n";
  auto trailing = ParseDxf(text, "g.dxf");
  ASSERT_TRUE(trailing.ok()) << trailing.status().ToString();
  EXPECT_FALSE(trailing->warnings.empty());
  // A UTF-8 byte order mark and classic Mac line ends.
  std::string mac = "\xEF\xBB\xBF" + Dxf({{0, "LINE"}, {10, "0"}, {20, "0"}, {11, "3"}, {21, "4"}});
  std::replace(mac.begin(), mac.end(), '\n', '\r');
  auto m = ParseDxf(mac, "mac.dxf");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_NEAR(Length(m->paths[0]), 5.0, 1e-12);
  // Binary DXF: a clear refusal.
  const std::string binary =
      std::string("AutoCAD Binary DXF\r\n\x1a\0", 22) + std::string(64, '\1');
  auto b = ParseDxf(binary, "bin.dxf");
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("binary DXF"), std::string::npos);
}

// unsupported_r2000.dxf: a DIMENSION whose *D1 block is present (a line, an arrowhead SOLID,
// two definition POINTs) and one whose block is missing; 3DFACE, SOLID, MESH, REGION, 3DSOLID,
// BODY, IMAGE, LEADER, XLINE, RAY, POINT; a paper-space VIEWPORT and LINE; an INSERT of a
// missing block; a SPLINE of fit points only; and a LINE.
TEST(Dxf, UnsupportedEntitiesAreCounted) {
  auto p = LoadDxf(DataPath("unsupported_r2000.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  const std::map<std::string, int> skipped = {
      {"3dface", 1}, {"mesh", 1},   {"region", 1},      {"3dsolid", 1},       {"body", 1},
      {"image", 1},  {"leader", 1}, {"xline", 1},       {"ray", 1},           {"point", 3},
      {"dimension", 1}, {"paper_space", 2}, {"missing_block", 1}, {"spline_fit_points", 1}};
  EXPECT_EQ(p->skipped, skipped);
  EXPECT_EQ(Count(p->converted, "dimension"), 1);
  EXPECT_EQ(Count(p->converted, "solid"), 2);
  EXPECT_EQ(Count(p->converted, "line"), 2);
  // The line, the dimension's line and arrowhead, the SOLID (a 10 x 10 square: vertices 1 2 4 3).
  ASSERT_EQ(p->paths.size(), 4u);
  const auto square = In(*p, {49, -1}, {61, 11});
  ASSERT_EQ(square.size(), 1u);
  EXPECT_NEAR(std::abs(Shoelace(square[0])), 100.0, 1e-9);
  const auto arrow = In(*p, {-1, -7}, {4, -3});
  ASSERT_EQ(arrow.size(), 1u);
  EXPECT_EQ(arrow[0].points.size(), 3u);  // a triangle: the fourth vertex repeats the third
  EXPECT_FALSE(p->warnings.empty());
}

std::string Nest(const std::string& blocks, const std::string& entities) {
  return "0\nSECTION\n2\nBLOCKS\n" + blocks + "0\nENDSEC\n0\nSECTION\n2\nENTITIES\n" + entities +
         "0\nENDSEC\n0\nEOF\n";
}

std::string Block(const std::string& name, const std::string& body) {
  return "0\nBLOCK\n2\n" + name + "\n70\n0\n10\n0\n20\n0\n30\n0\n" + body + "0\nENDBLK\n";
}

std::string InsertOf(const std::string& name, const std::string& extra = "") {
  return "0\nINSERT\n2\n" + name + "\n10\n0\n20\n0\n30\n0\n" + extra;
}

const char kLine[] = "0\nLINE\n10\n0\n20\n0\n11\n1\n21\n0\n";

TEST(Dxf, BlockCyclesAndLimits) {
  // A inserts B inserts A.
  auto cycle = ParseDxf(Nest(Block("A", InsertOf("B")) + Block("B", kLine + InsertOf("a")),
                             InsertOf("A")),
                        "cycle.dxf");
  ASSERT_FALSE(cycle.ok());
  EXPECT_EQ(cycle.status().code(), StatusCode::kParseError);
  EXPECT_NE(cycle.status().message().find("inserts itself (A -> B -> A)"), std::string::npos)
      << cycle.status().message();
  EXPECT_NE(cycle.status().message().find("line "), std::string::npos);
  // 40 levels of nesting.
  std::string deep;
  for (int k = 0; k < 40; ++k) {
    deep += Block("L" + std::to_string(k),
                  k == 0 ? std::string(kLine) : InsertOf("L" + std::to_string(k - 1)));
  }
  auto too_deep = ParseDxf(Nest(deep, InsertOf("L39")), "deep.dxf");
  EXPECT_EQ(too_deep.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(too_deep.status().message().find("nested deeper than 32"), std::string::npos);
  // An array of 1000 x 1000 copies.
  auto array = ParseDxf(Nest(Block("A", kLine), InsertOf("A", "70\n1000\n71\n1000\n")), "arr.dxf");
  EXPECT_EQ(array.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(array.status().message().find("1000 x 1000"), std::string::npos);
  // Each level inserting the previous twice, 30 levels: 2^30 lines from a 3 kB file.
  std::string doubling;
  for (int k = 0; k < 30; ++k) {
    const std::string prev = "D" + std::to_string(k - 1);
    doubling += Block("D" + std::to_string(k),
                      k == 0 ? std::string(kLine) : InsertOf(prev) + InsertOf(prev, "10\n5\n"));
  }
  auto doubled = ParseDxf(Nest(doubling, InsertOf("D29")), "double.dxf");
  EXPECT_EQ(doubled.status().code(), StatusCode::kOutOfRange);
  // A missing block is counted; the rest of the drawing is kept.
  auto missing = ParseDxf(Nest("", InsertOf("NONE") + kLine), "m.dxf");
  ASSERT_TRUE(missing.ok()) << missing.status().ToString();
  EXPECT_EQ(Count(missing->skipped, "missing_block"), 1);
}

// Every corpus file cut at each line, and with bytes changed at random (fixed seed): the
// reader returns a result or an error, never crashes, hangs or reads out of bounds (run it
// under ASan/UBSan to see the last two).
TEST(Dxf, DamagedFilesFailCleanly) {
  const char* files[] = {"blocks_nested_r2000.dxf", "ocs_mirror_r2000.dxf", "hatch_r2000.dxf",
                         "chain_r12.dxf", "mesh_r12.dxf", "unsupported_r2000.dxf",
                         "text_r2000.dxf", "ocs_polyline_crlf_r12.dxf"};
  std::mt19937 rng(42);
  int runs = 0, failed = 0;
  auto check = [&](const std::string& text) {
    auto r = ParseDxf(text, "damaged.dxf");
    ++runs;
    if (!r.ok()) {
      ++failed;
      EXPECT_FALSE(r.status().message().empty());
    }
  };
  for (const char* f : files) {
    const std::string text = ReadData(f);
    ASSERT_FALSE(text.empty()) << f;
    for (size_t at = text.find('\n'); at != std::string::npos; at = text.find('\n', at + 1)) {
      check(text.substr(0, at + 1));
    }
    const char kBytes[] = "0123456789-.eE \n\r\t\x00\xff\x80" "ABCXYZ%\\{}";
    for (int k = 0; k < 300; ++k) {
      std::string t = text;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        t[rng() % t.size()] = kBytes[rng() % (sizeof(kBytes) - 1)];
      }
      check(t);
    }
  }
  EXPECT_GT(runs, 1000);
  EXPECT_GT(failed, 0);
}

// text_r2000.dxf: TEXT in a TrueType style (arial.ttf) left, centred on (50,20), right-aligned
// on (100,40), aligned between (0,60) and (40,60), turned 90 degrees at (120,0), top-aligned at
// (0,80), in an SHX style (romans.shx), mirrored (backward) at (150,0), one empty; an MTEXT of
// two lines with inline codes at (0,140), height 3; an ATTRIB after an INSERT of a block whose
// ATTDEF is a template.
TEST(Dxf, Texts) {
  auto p = LoadDxf(DataPath("text_r2000.dxf"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(Count(p->converted, "text"), 8);
  EXPECT_EQ(Count(p->converted, "mtext"), 1);
  EXPECT_EQ(Count(p->converted, "attrib"), 1);
  EXPECT_EQ(p->texts, 10);
  EXPECT_EQ(p->ignored_commands, 2);  // the empty TEXT and the ATTDEF template
  // The Hershey fonts are ASCII: the degree sign of "ENGRAVE %%d" is missing, and counted.
  const std::map<std::string, int> missing = {{"missing_glyph", 1}};
  EXPECT_EQ(p->skipped, missing);
  bool shx_warned = false;
  for (const auto& w : p->warnings) {
    shx_warned = shx_warned || w.find("hershey:rowmans") != std::string::npos;
  }
  EXPECT_TRUE(shx_warned);
  // Cap height 5: the glyph boxes (within a font's overshoot and side bearings, 10 %).
  const Extent left = Extents(Of(In(*p, {-1, -1}, {40, 6})));
  EXPECT_NEAR(left.lo.y(), 0.0, 0.5);
  EXPECT_NEAR(left.hi.y(), 5.0, 0.5);
  EXPECT_NEAR(left.lo.x(), 0.0, 0.8);
  const Extent centre = Extents(Of(In(*p, {20, 19}, {80, 26})));
  EXPECT_NEAR(0.5 * (centre.lo.x() + centre.hi.x()), 50.0, 0.5);
  const Extent right = Extents(Of(In(*p, {40, 39}, {101, 46})));
  EXPECT_NEAR(right.hi.x(), 100.0, 0.8);
  const Extent aligned = Extents(Of(In(*p, {-1, 59}, {41, 69})));
  EXPECT_NEAR(aligned.lo.x(), 0.0, 0.5);
  EXPECT_NEAR(aligned.hi.x(), 40.0, 0.5);
  const Extent up = Extents(Of(In(*p, {110, -1}, {121, 30})));
  EXPECT_NEAR(up.lo.x(), 115.0, 0.5);  // reads upward: the cap height spans x, left of the point
  EXPECT_LE(up.hi.x(), 120.3);
  EXPECT_NEAR(up.lo.y(), 0.0, 0.8);
  EXPECT_GT(up.hi.y(), 7.0);
  const Extent top = Extents(Of(In(*p, {-1, 70}, {40, 81})));
  EXPECT_NEAR(top.hi.y(), 80.0, 0.5);
  const Extent back = Extents(Of(In(*p, {120, -1}, {151, 6})));
  EXPECT_NEAR(back.hi.x(), 150.0, 0.8);  // mirrored: runs to the left of its point
  const Extent mtext = Extents(Of(In(*p, {-1, 125}, {60, 141})));
  EXPECT_NEAR(mtext.hi.y(), 140.0, 0.4);             // top attachment: cap top on the point
  EXPECT_NEAR(mtext.lo.y(), 140 - 3 - 5, 1.5);       // the second baseline 5/3 x 3 lower
  std::vector<Polyline> glyphs;  // of the ATTRIB, without the block's 30 mm frame
  for (const auto& l : In(*p, {201, 1}, {229, 7})) {
    if (Extents(Of({l})).hi.x() - Extents(Of({l})).lo.x() < 25) glyphs.push_back(l);
  }
  const Extent attrib = Extents(Of(glyphs));
  EXPECT_NEAR(attrib.lo.x(), 202.0, 0.8);
}

// MTEXT codes: {\F...;} an SHX font file for the text that follows (drawn as its Hershey
// twin), \P line breaks, \S a stacked fraction (drawn inline, approximately). Bottom-left
// attachment (71 = 7) puts the last baseline on the point, the lines 5/3 cap heights apart.
TEST(Dxf, MtextInlineCodes) {
  auto p = ParseDxf(Dxf({{0, "MTEXT"}, {10, "0"}, {20, "0"}, {30, "0"}, {40, "2.5"}, {71, "7"},
                         {1, "{\\Fromans.shx;AB}\\PCD\\P\\S1/2;"}}),
                    "m.dxf");
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(p->texts, 1);
  EXPECT_EQ(Count(p->converted, "mtext"), 1);
  for (const auto& l : p->paths) EXPECT_FALSE(l.closed);  // single strokes
  bool hershey = false, approx = false;
  for (const auto& w : p->warnings) {
    hershey = hershey || w.find("hershey:rowmans") != std::string::npos;
    approx = approx || w.find("approximately") != std::string::npos;
  }
  EXPECT_TRUE(hershey);
  EXPECT_TRUE(approx);
  const Extent e = Extents(*p);
  const double first_baseline = 2 * 5.0 / 3.0 * 2.5;
  EXPECT_NEAR(e.hi.y(), first_baseline + 2.5, 0.3);  // the cap top of "AB"
  EXPECT_GT(e.lo.y(), -1.5);                          // "1/2" on y = 0, the slash below it
  EXPECT_LT(e.lo.y(), 0.1);
}

}  // namespace
}  // namespace insitu::pattern
