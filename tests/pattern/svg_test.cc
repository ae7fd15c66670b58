// SVG input: units from width/height over viewBox, y flipped up, shapes, path commands
// (absolute and relative, curves and arcs flattened within tolerance), transforms, and errors
// that name the element; <use> and <symbol>, rounded rectangles, elliptic arcs, the CSS
// cascade, hidden elements, text, and the count of what is not drawn, on the hand-written files
// of tests/pattern/data/svg/ (each says in its comments what it should give).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "insitu/pattern/text.h"
#include "insitu/pattern/vector.h"

namespace insitu::pattern {
namespace {

// 1 user unit = 1 mm.
std::string Svg(const std::string& body) {
  return "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"100mm\" height=\"100mm\" "
         "viewBox=\"0 0 100 100\">" +
         body + "</svg>";
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
  auto p = ParseSvg(
      "<svg width=\"20mm\" height=\"10mm\" viewBox=\"0 0 200 100\">"
      "<rect x=\"10\" y=\"10\" width=\"100\" height=\"50\"/></svg>",
      "t.svg");
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
  auto big =
      ParseSvg(Svg("<polygon points=\"0,0 1,0 2,0 3,0 4,0 4,4 3,4 2,4 1,4 0,4\"/>"), "b.svg");
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
  // Nothing markable: refused, saying what was there.
  auto image = ParseSvg(Svg("<image width=\"10\" height=\"10\" href=\"a.png\"/>"), "e.svg");
  EXPECT_EQ(image.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(image.status().message().find("1 svg_image"), std::string::npos)
      << image.status().message();
  EXPECT_FALSE(ParseSvg(Svg("<g transform=\"spin(3)\"><line x2=\"1\"/></g>"), "t.svg").ok());
  EXPECT_EQ(LoadSvg("/nonexistent.svg").status().code(), StatusCode::kNotFound);
}

std::string DataPath(const std::string& name) {
  return std::string(INSITU_SOURCE_DIR) + "/tests/pattern/data/svg/" + name;
}

std::string ReadData(const std::string& name) {
  std::ifstream f(DataPath(name), std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

struct Box {
  Eigen::Vector2d lo{INFINITY, INFINITY}, hi{-INFINITY, -INFINITY};
  void Add(const Eigen::Vector2d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
};

Box Extents(const Polyline& p) {
  Box b;
  for (const auto& q : p.points) b.Add(q);
  return b;
}

// Along the path, with the closing segment of a closed one. An outline (fill none) repeats its
// first point, so its closing segment is already there.
double Length(const Polyline& p) {
  double l = 0;
  for (size_t i = 1; i < p.points.size(); ++i) l += (p.points[i] - p.points[i - 1]).norm();
  if (p.closed && p.points.size() > 2) l += (p.points.front() - p.points.back()).norm();
  return l;
}

// Shoelace area of the polygon the points make (closed or an outline back to its start).
double Area(const Polyline& p) {
  double a = 0;
  for (size_t i = 0; i < p.points.size(); ++i) {
    const auto& u = p.points[i];
    const auto& v = p.points[(i + 1) % p.points.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return std::abs(a) / 2;
}

// Perimeter of the ellipse with semi-axes a, b: the integral of |d/dt (a cos t, b sin t)|
// by the midpoint rule, exact to rounding for this smooth periodic integrand.
double EllipsePerimeter(double a, double b) {
  constexpr int kSteps = 20000;
  double s = 0;
  for (int k = 0; k < kSteps; ++k) {
    const double t = 2 * M_PI * (k + 0.5) / kSteps;
    s += std::hypot(a * std::sin(t), b * std::cos(t));
  }
  return s * 2 * M_PI / kSteps;
}

// The features below are 2 to 60 mm across and flattened within 5 um: a chord of an arc of
// radius r with sagitta s is shorter than its arc by about s / (3 r) (0.03 % at r = 5 mm) and
// cuts at most 2/3 s per mm of outline from an area (0.01 % here). Lengths, areas and extents
// are held to the 0.5 % a design tolerance asks; extents, where a vertex sits on the extreme,
// to the 5 um tolerance.
constexpr double kRel = 0.005;
constexpr double kTolMm = 0.005;

#define EXPECT_REL(value, expected) EXPECT_NEAR(value, expected, kRel* std::abs(expected))

void ExpectBox(const Polyline& p, double x0, double x1, double y0, double y1) {
  const Box b = Extents(p);
  EXPECT_NEAR(b.lo.x(), x0, kTolMm);
  EXPECT_NEAR(b.hi.x(), x1, kTolMm);
  EXPECT_NEAR(b.lo.y(), y0, kTolMm);
  EXPECT_NEAR(b.hi.y(), y1, kTolMm);
}

TEST(Svg, UseOfSymbolFitsItsViewBox) {
  auto p = LoadSvg(DataPath("use_symbol.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  // Three uses; the symbols and the unused <rect> in <defs> are not drawn where they stand.
  ASSERT_EQ(p->paths.size(), 3u);
  EXPECT_EQ(p->converted["use"], 3);
  EXPECT_EQ(p->units, "mm");
  // meet: a 20 x 20 square at x 10..30, y 5..25 (y up: -25..-5).
  ExpectBox(p->paths[0], 10, 30, -25, -5);
  EXPECT_REL(Area(p->paths[0]), 400.0);
  // none: the circle of the 10 x 10 symbol stretched to an ellipse of 15 x 10 semi-axes.
  ExpectBox(p->paths[1], 50, 80, -70, -50);
  EXPECT_TRUE(p->paths[1].closed);
  EXPECT_REL(Area(p->paths[1]), M_PI * 15 * 10);
  EXPECT_REL(Length(p->paths[1]), EllipsePerimeter(15, 10));
  // xMaxYMax meet: the square pushed to the right of the 30 x 20 viewport.
  ExpectBox(p->paths[2], 15, 35, -80, -60);
}

TEST(Svg, UseOfGroupComposesTransforms) {
  auto p = LoadSvg(DataPath("use_group.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 5u);
  // use transform, then the use's x/y, then the group's rotate(90).
  ExpectBox(p->paths[0], 55, 57, -20, -10);
  EXPECT_REL(Area(p->paths[0]), 20.0);
  // A use of a use.
  ExpectBox(p->paths[1], 20, 22, -50, -40);
  // x/y inside the use's scale(2).
  ExpectBox(p->paths[2], 20, 24, -80, -60);
  EXPECT_REL(Area(p->paths[2]), 80.0);
  // The circle inherits its fill from the use: an area under the plain use, an outline
  // (back to its start, not closed) under the one with fill none.
  ExpectBox(p->paths[3], 77, 83, -83, -77);
  EXPECT_TRUE(p->paths[3].closed);
  EXPECT_FALSE(p->paths[4].closed);
  EXPECT_EQ(p->paths[4].points.front(), p->paths[4].points.back());
  ExpectBox(p->paths[4], 77, 83, -23, -17);
  EXPECT_REL(Length(p->paths[4]), 2 * M_PI * 3);
  EXPECT_EQ(p->converted["use"], 6);  // five in the body, one inside a referenced use
}

// Perimeter 2 (w + h) - (8 - 2 pi) r and area w h - (4 - pi) r^2 for round corners; with
// elliptic corners rx, ry the corners make one ellipse's perimeter and cut (4 - pi) rx ry.
TEST(Svg, RoundedRectangles) {
  auto p = LoadSvg(DataPath("rounded_rect.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 5u);
  const Polyline& a = p->paths[0];  // 40 x 20, r = 5
  EXPECT_TRUE(a.closed);
  ExpectBox(a, 10, 50, -30, -10);
  EXPECT_REL(Length(a), 2 * (40 + 20) - (8 - 2 * M_PI) * 5);
  EXPECT_REL(Area(a), 40 * 20 - (4 - M_PI) * 25);
  const Polyline& b = p->paths[1];  // rx 30 clamped to 20, ry 4
  ExpectBox(b, 10, 50, -60, -40);
  EXPECT_REL(Length(b), 2 * (40 - 2 * 20) + 2 * (20 - 2 * 4) + EllipsePerimeter(20, 4));
  EXPECT_REL(Area(b), 40 * 20 - (4 - M_PI) * 20 * 4);
  const Polyline& c = p->paths[2];  // ry alone: r = 3
  EXPECT_REL(Length(c), 2 * (10 + 10) - (8 - 2 * M_PI) * 3);
  EXPECT_REL(Area(c), 100 - (4 - M_PI) * 9);
  const Polyline& d = p->paths[3];  // rx = 0: square
  EXPECT_EQ(d.points.size(), 4u);
  EXPECT_NEAR(Area(d), 100.0, 1e-9);
  const Polyline& e = p->paths[4];  // fill none: an outline of the rounded shape
  EXPECT_FALSE(e.closed);
  EXPECT_REL(Length(e), 2 * (30 + 20) - (8 - 2 * M_PI) * 5);
  VectorPattern outline_only;
  outline_only.paths.push_back(e);
  EXPECT_FALSE(HatchPolygons(outline_only, 0.1, 0.0).ok());
}

// Arcs against the ellipses they belong to. In page coordinates (SVG's y down) the flattened
// points lie on the ellipse to rounding, since every one is computed on it.
TEST(Svg, EllipticArcsAgainstTheirEllipses) {
  auto p = LoadSvg(DataPath("elliptic_arcs.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 6u);
  // Half of a = 30, b = 10 about (50, 30), turned 30 degrees, closed along its major axis.
  const Polyline& half = p->paths[0];
  EXPECT_TRUE(half.closed);
  const double c30 = std::cos(M_PI / 6), s30 = std::sin(M_PI / 6);
  const Eigen::Vector2d from(50 - 30 * c30, 30 - 30 * s30), to(50 + 30 * c30, 30 + 30 * s30);
  for (const auto& q : half.points) {
    const Eigen::Vector2d page(q.x(), -q.y());
    const Eigen::Vector2d d = page - Eigen::Vector2d(50, 30);
    const double u = d.x() * c30 + d.y() * s30, v = -d.x() * s30 + d.y() * c30;
    EXPECT_NEAR(u * u / 900 + v * v / 100, 1.0, 1e-9);
    // sweep 1 turns clockwise on the page: the half on the right of from -> to (page y down).
    const Eigen::Vector2d a = to - from, b = page - from;
    EXPECT_LE(a.x() * b.y() - a.y() * b.x(), 1e-6);
  }
  EXPECT_REL(Area(half), M_PI * 30 * 10 / 2);
  EXPECT_REL(Length(half), EllipsePerimeter(30, 10) / 2 + 60);
  // Radii 2 x 1 scaled up by 5 (the endpoints are 20 apart on the major axis): half of
  // 10 x 5, below the chord y = 80 on the page (y up: -85..-80).
  const Polyline& grown = p->paths[1];
  ExpectBox(grown, 10, 30, -85, -80);
  EXPECT_REL(Area(grown), M_PI * 10 * 5 / 2);
  EXPECT_REL(Length(grown), EllipsePerimeter(10, 5) / 2 + 20);
  // The four flag combinations: the circle each turns about and the segment it closes, a
  // quarter circle's (r^2 / 2 (pi / 2 - 1)) or three quarters' (r^2 / 2 (3 pi / 2 + 1)).
  const struct {
    double cx, cy;
    bool large;
  } arcs[] = {{60, 80, false}, {70, 70, true}, {70, 70, false}, {60, 80, true}};
  for (int k = 0; k < 4; ++k) {
    const Polyline& arc = p->paths[2 + k];
    for (const auto& q : arc.points) {
      EXPECT_NEAR((Eigen::Vector2d(q.x(), -q.y()) - Eigen::Vector2d(arcs[k].cx, arcs[k].cy)).norm(),
                  10.0, 1e-9)
          << "arc " << k;
    }
    EXPECT_REL(Area(arc), arcs[k].large ? 50 * (1.5 * M_PI + 1) : 50 * (M_PI / 2 - 1));
    EXPECT_REL(Length(arc), (arcs[k].large ? 15 * M_PI : 5 * M_PI) + std::sqrt(200.0));
  }
}

// css.svg: thirteen shapes left to right, each an area (filled) or an outline (fill none) as
// the cascade decides.
TEST(Svg, CssCascadeDecidesAreasAndOutlines) {
  auto p = LoadSvg(DataPath("css.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 13u);
  const bool area[] = {false, true,  false, true,  true, false, false,
                       true,  false, true,  false, true, false};
  const char* why[] = {"class fill:none",
                       "id beats class",
                       "type selector",
                       "class beats type",
                       "style attribute beats CSS",
                       "CSS beats presentation attribute",
                       "descendant selector",
                       "outside the descendant's group",
                       "child selector",
                       "not a child",
                       "!important beats style",
                       "unsupported selector applies nothing",
                       "inherited from a group's style"};
  for (int k = 0; k < 13; ++k) {
    EXPECT_EQ(p->paths[k].closed, area[k]) << "shape " << k << ": " << why[k];
    EXPECT_NEAR(Extents(p->paths[k]).lo.x(), 10 * k + 1, kTolMm) << "shape " << k;
  }
  // Only the areas are hatched: circles of r 4 (1, 4, 7), the 8 x 8 square (3), the triangle of
  // base and height 8 (9) and the 4 x 3 ellipse (11). Hatch lines 0.02 mm apart lose or gain
  // at most a spacing's strip along the outlines (~150 mm x 0.02 mm = 3 mm^2, 1 %).
  const double areas = 3 * M_PI * 16 + 64 + 32 + M_PI * 12;
  EXPECT_NEAR(HatchedArea(*p, 0.02), areas, 0.01 * areas);
  // The unsupported selector is reported.
  ASSERT_EQ(p->warnings.size(), 1u);
  EXPECT_NE(p->warnings[0].find("ellipse:hover"), std::string::npos);
  // A file of class fill:none shapes only has nothing to hatch.
  auto outlines = ParseSvg(Svg("<style>.cut{fill:none;stroke:#000}</style>"
                               "<rect class=\"cut\" width=\"10\" height=\"10\"/>"
                               "<circle class=\"cut\" cx=\"30\" cy=\"30\" r=\"5\"/>"),
                           "cut.svg");
  ASSERT_TRUE(outlines.ok()) << outlines.status().ToString();
  EXPECT_EQ(HatchPolygons(*outlines, 0.1, 0.0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(
      Outline(*outlines).size(),
      4u + (outlines->paths[1].points.size() - 1));  // the square's 4 sides, the circle's chords
}

TEST(Svg, HiddenElementsAreSkippedAndCounted) {
  auto p = LoadSvg(DataPath("hidden.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  // Drawn: the rectangle that made itself visible again and the circle.
  ASSERT_EQ(p->paths.size(), 2u);
  ExpectBox(p->paths[0], 20, 30, -20, -10);
  EXPECT_TRUE(p->paths[1].closed);
  // The hidden layer (one, with its children), the class display:none, display="none",
  // visibility hidden, opacity 0; and the shape painted neither way.
  EXPECT_EQ(p->skipped["svg_hidden"], 5);
  EXPECT_EQ(p->skipped["svg_unpainted"], 1);
  EXPECT_EQ(p->skipped.size(), 2u);
}

TEST(Svg, UnsupportedConstructsAreCounted) {
  auto p = LoadSvg(DataPath("unsupported.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  const std::map<std::string, int> expected = {
      {"svg_animation", 1}, {"svg_clip_path", 1},       {"svg_degenerate", 1},
      {"svg_filter", 1},    {"svg_flowed_text", 1},     {"svg_foreign_object", 1},
      {"svg_gradient", 1},  {"svg_image", 1},           {"svg_marker", 1},
      {"svg_mask", 1},      {"svg_pattern", 1},         {"svg_switch", 1},
      {"svg_text_path", 1}, {"svg_unknown_element", 1}, {"svg_use", 2}};
  EXPECT_EQ(p->skipped, expected);
  // Drawn anyway: the six shapes whose paint, clip, mask, marker or filter is not applied,
  // the switch's rectangle, the animated rectangle and the text path's curve.
  EXPECT_EQ(p->paths.size(), 9u);
  EXPECT_EQ(p->converted["rect"], 7);
  EXPECT_EQ(p->converted["path"], 2);
  EXPECT_EQ(p->texts, 0);
  const auto warned = [&](const std::string& what) {
    return std::any_of(p->warnings.begin(), p->warnings.end(),
                       [&](const std::string& w) { return w.find(what) != std::string::npos; });
  };
  EXPECT_TRUE(warned("clip-path is not applied"));
  EXPECT_TRUE(warned("mask is not applied"));
  EXPECT_TRUE(warned("<blink>"));
  EXPECT_TRUE(warned("other.svg#logo"));
  EXPECT_TRUE(warned("#no_such_id"));
  EXPECT_TRUE(warned("Convert to Text"));
}

// Illustrator's export: the switch takes the drawing, not Illustrator's private data; classes
// decide outline and area; sizes in mm.
TEST(Svg, IllustratorExport) {
  auto p = LoadSvg(DataPath("illustrator.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->paths.size(), 2u);
  EXPECT_EQ(p->units, "mm");
  EXPECT_FALSE(p->paths[0].closed);  // .st0: fill none
  ExpectBox(p->paths[0], 5, 45, -25, -5);
  EXPECT_TRUE(p->paths[1].closed);  // .st1: filled
  EXPECT_REL(Area(p->paths[1]), M_PI * 100);
  EXPECT_EQ(p->skipped["svg_switch"], 1);
}

TEST(Svg, UseCyclesAreRefusedAndTheRestDrawn) {
  auto p = LoadSvg(DataPath("use_cycle.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  // Group a's square, drawn where it stands, through b's use of a (y 20) and through a's use of
  // b's use of a (x 20, y 20); the second lap of each cycle, the self-reference and the use
  // inside the group it names are refused.
  ASSERT_EQ(p->paths.size(), 3u);
  EXPECT_EQ(p->skipped["svg_use"], 4);
  int cycles = 0;
  for (const std::string& w : p->warnings) {
    cycles += w.find("comes back to itself") != std::string::npos ||
              w.find("holds the <use>") != std::string::npos;
  }
  EXPECT_EQ(cycles, 4);
}

// Seven levels of ten uses each would be 10^7 rectangles: refused at the element limit, fast.
TEST(Svg, UseBombIsRefused) {
  auto p = LoadSvg(DataPath("use_bomb.svg"));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(p.status().message().find("elements to draw once <use> is expanded"), std::string::npos)
      << p.status().message();
}

TEST(Svg, UnitsLengthsAndViewports) {
  auto tenth = ParseSvg(
      "<svg width=\"20mm\" height=\"10mm\" viewBox=\"0 0 200 100\">"
      "<rect width=\"10\" height=\"10\"/></svg>",
      "u.svg");
  ASSERT_TRUE(tenth.ok());
  EXPECT_EQ(tenth->units, "mm (1 user unit = 0.1 mm)");
  EXPECT_TRUE(tenth->warnings.empty());
  auto inch = ParseSvg(
      "<svg width=\"4in\" height=\"2in\" viewBox=\"0 0 4 2\">"
      "<rect width=\"1\" height=\"1\"/></svg>",
      "i.svg");
  ASSERT_TRUE(inch.ok());
  EXPECT_EQ(inch->units, "in");
  EXPECT_NEAR(Extents(inch->paths[0]).hi.x(), 25.4, 1e-9);
  // No size: 1 user unit = 1 px = 1/96 in, with a warning about Illustrator's 1/72 in.
  auto px =
      ParseSvg("<svg viewBox=\"0 0 96 96\"><rect width=\"96\" height=\"48\"/></svg>", "p.svg");
  ASSERT_TRUE(px.ok());
  EXPECT_EQ(px->units, "px (1/96 in)");
  EXPECT_NEAR(Extents(px->paths[0]).hi.x(), 25.4, 1e-9);
  ASSERT_FALSE(px->warnings.empty());
  EXPECT_NE(px->warnings[0].find("1/72 in"), std::string::npos);
  // Lengths with units in attributes are CSS lengths in user units (px); percentages are of
  // the viewBox.
  auto lengths = ParseSvg(
      "<svg width=\"100mm\" height=\"100mm\">"
      "<rect x=\"1cm\" width=\"25.4mm\" height=\"1in\"/></svg>",
      "l.svg");
  ASSERT_TRUE(lengths.ok()) << lengths.status().ToString();
  ExpectBox(lengths->paths[0], 10, 35.4, -25.4, 0);
  auto percent = ParseSvg(Svg("<rect x=\"10%\" width=\"50%\" height=\"10%\"/>"), "c.svg");
  ASSERT_TRUE(percent.ok());
  ExpectBox(percent->paths[0], 10, 60, -10, 0);
  // The root's viewBox is fitted by preserveAspectRatio (xMidYMid meet): 100 x 100 user units
  // on 100 x 50 mm is 0.5 mm per unit, centred across.
  auto meet = ParseSvg(
      "<svg width=\"100mm\" height=\"50mm\" viewBox=\"0 0 100 100\">"
      "<rect width=\"100\" height=\"100\"/></svg>",
      "m.svg");
  ASSERT_TRUE(meet.ok());
  ExpectBox(meet->paths[0], 25, 75, -50, 0);
  // A nested <svg> is a viewport: 2 x 2 units onto 20 x 20 at (10, 10).
  auto nested =
      ParseSvg(Svg("<svg x=\"10\" y=\"10\" width=\"20\" height=\"20\" viewBox=\"0 0 2 2\">"
                   "<rect width=\"2\" height=\"2\"/></svg>"),
               "n.svg");
  ASSERT_TRUE(nested.ok());
  ExpectBox(nested->paths[0], 10, 30, -30, -10);
}

// DejaVu Sans: cap height 1493 / 2048 em (its 'H' spans y 0..1493), 'H' advance 1540 and side
// bearings 201 / 2048 em on either side. The glyphs are flattened within 5 um, and their
// straight stems and bars put the extremes on vertices: held to 0.5 % (0.04 mm at 10 mm).
constexpr double kCapEm = 1493.0 / 2048.0;
constexpr double kAdvanceEm = 1540.0 / 2048.0;
constexpr double kBearingEm = 201.0 / 2048.0;

TEST(Svg, TextGlyphsHaveTheCapHeightAndAnchors) {
  auto p = LoadSvg(DataPath("text.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(p->texts, 3);
  EXPECT_EQ(p->converted["text"], 3);
  EXPECT_EQ(p->converted["glyph"], 6);
  ASSERT_EQ(p->paths.size(), 6u);  // one closed outline per 'H'
  for (const Polyline& h : p->paths) {
    EXPECT_TRUE(h.closed);
    const Box b = Extents(h);
    EXPECT_REL(b.hi.y() - b.lo.y(), 10 * kCapEm);
  }
  // Baseline y = 30 (y up: -30), starting at x = 10 after the left bearing.
  const Box first = Extents(p->paths[0]);
  EXPECT_NEAR(first.lo.y(), -30, kTolMm);
  EXPECT_NEAR(first.lo.x(), 10 + 10 * kBearingEm, kRel * 10);
  // middle: "HHH" centred on x = 50 ('H' is symmetric in its advance).
  Box mid;
  for (int k = 1; k <= 3; ++k) {
    mid.Add(Extents(p->paths[k]).lo);
    mid.Add(Extents(p->paths[k]).hi);
  }
  EXPECT_NEAR(0.5 * (mid.lo.x() + mid.hi.x()), 50, kRel * 10);
  // end: "HH" ends at x = 90, its ink one right bearing before.
  EXPECT_NEAR(Extents(p->paths[5]).hi.x(), 90 - 10 * kBearingEm, kRel * 10);
  EXPECT_TRUE(p->warnings.empty()) << p->warnings[0];
}

TEST(Svg, TextLinesFontListAndRuns) {
  auto p = LoadSvg(DataPath("text_lines.svg"));
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ(p->texts, 2);
  // The first family of the list is not installed, the second is: no substitution warning.
  for (const std::string& w : p->warnings) ADD_FAILURE() << "unexpected warning: " << w;
  ASSERT_EQ(p->paths.size(), 6u);
  // Line 1 at y = 20, line 2 at y = 40, each from x = 10.
  EXPECT_NEAR(Extents(p->paths[0]).lo.y(), -20, kTolMm);
  EXPECT_NEAR(Extents(p->paths[1]).lo.y(), -40, kTolMm);
  EXPECT_NEAR(Extents(p->paths[1]).lo.x(), 10 + 10 * kBearingEm, kRel * 10);
  // Line 2's runs follow each other: the 20 px 'H' after one 10 px advance, the last 'H'
  // after that and the 20 px advance.
  const Box big = Extents(p->paths[2]);
  EXPECT_REL(big.hi.y() - big.lo.y(), 20 * kCapEm);
  EXPECT_NEAR(big.lo.x(), 10 + 10 * kAdvanceEm + 20 * kBearingEm, kRel * 10);
  EXPECT_NEAR(Extents(p->paths[3]).lo.x(), 10 + 10 * kAdvanceEm + 20 * kAdvanceEm + 10 * kBearingEm,
              kRel * 10);
  // fill none: the 'O' is two outlines (outer and counter), not areas.
  EXPECT_FALSE(p->paths[4].closed);
  EXPECT_FALSE(p->paths[5].closed);
}

// Files from outside: garbage numbers, overflowing transforms, broken CSS, deep nesting and
// mutated copies of the corpus give an error or a pattern, never a crash (run under ASan in the
// sanitizer build).
TEST(Svg, MalformedInputIsRefusedOrRead) {
  const struct {
    const char* svg;
    StatusCode code;
  } cases[] = {
      {"<svg><rect width=\"nan\" height=\"1\"/></svg>", StatusCode::kParseError},
      {"<svg><rect width=\"inf\" height=\"1\"/></svg>", StatusCode::kParseError},
      {"<svg><rect width=\"0x10\" height=\"1\"/></svg>", StatusCode::kParseError},
      {"<svg><path d=\"M 0 0 L 1e999 0\"/></svg>", StatusCode::kParseError},
      {"<svg><path d=\"M 0 0 L 1e\"/></svg>", StatusCode::kParseError},
      {"<svg><rect width=\"1e300\" height=\"1e300\" transform=\"scale(1e300)\"/></svg>",
       StatusCode::kInvalidArgument},
      {"<svg width=\"1e300mm\" viewBox=\"0 0 1e-300 1e-300\"><rect width=\"1\" "
       "height=\"1\"/></svg>",
       StatusCode::kParseError},
      {"<svg><polygon points=\"0,0 1\"/></svg>", StatusCode::kParseError},
      {"<svg><rect width=\"-1\" height=\"1\"/></svg>", StatusCode::kParseError},
      {"<svg><circle r=\"-1\"/></svg>", StatusCode::kParseError},
      {"<svg width=\"9\" height=\"9\"><svg viewBox=\"0 0 0 1\"><rect width=\"1\" height=\"1\"/>"
       "</svg></svg>",
       StatusCode::kParseError},
      {"<svg><svg viewBox=\"0 0 10 10\"><rect width=\"1\" height=\"1\"/></svg></svg>",
       StatusCode::kOk},
      {"<svg><style>}}}{{{ @media { .a { </style><rect width=\"1\" height=\"1\"/></svg>",
       StatusCode::kOk},
      {"<svg><style>/* unterminated</style><rect style=\";;:;fill::\" width=\"1\" "
       "height=\"1\"/></svg>",
       StatusCode::kOk},
      {"<svg><path d=\"M0 0 A 0 0 0 0 0 0 0 A 1e-300 1e300 45 1 1 1 1 A 1 1 1e300 1 1 2 "
       "2\"/></svg>",
       StatusCode::kOk},
      {"<svg><path d=\"M0 0 C 1e150 1e150 -1e150 1e150 1 1\"/></svg>", StatusCode::kOk},
      {"<svg><use href=\"#\"/><use href=\"\"/><use/><line x2=\"1\"/></svg>", StatusCode::kOk},
  };
  for (const auto& c : cases) {
    auto p = ParseSvg(c.svg, "bad.svg");
    EXPECT_EQ(p.ok() ? StatusCode::kOk : p.status().code(), c.code) << c.svg;
  }
  // A style sheet that costs more than it can be worth: 10^4 descendant rules tried on each of
  // 10^3 rectangles.
  std::string css = "<style>";
  for (int k = 0; k < 10000; ++k) css += "g g g g rect{fill:none}";
  std::string rects = "</style>";
  for (int k = 0; k < 1000; ++k) rects += "<rect width=\"1\" height=\"1\"/>";
  auto costly = ParseSvg(Svg(css + rects), "css.svg");
  EXPECT_EQ(costly.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(costly.status().message().find("style sheet costs too much"), std::string::npos)
      << costly.status().message();
  // tinyxml2 refuses elements nested deeper than 100: a parse error, not a deep recursion.
  std::string deep;
  for (int k = 0; k < 200; ++k) deep += "<g>";
  deep += "<line x2=\"1\"/>";
  for (int k = 0; k < 200; ++k) deep += "</g>";
  EXPECT_EQ(ParseSvg("<svg>" + deep + "</svg>", "deep.svg").status().code(),
            StatusCode::kParseError);
  // Mutations of the corpus (fixed seed): bytes replaced by SVG's syntax characters, or the
  // file cut short.
  std::mt19937 rng(7);
  const std::string alphabet = "<>/=\"' \n0123456789.-+eE#;:{}(),%MmLlAaZzchv";
  for (const char* name :
       {"use_symbol.svg", "use_group.svg", "rounded_rect.svg", "elliptic_arcs.svg", "css.svg",
        "hidden.svg", "unsupported.svg", "use_cycle.svg", "illustrator.svg", "text_lines.svg"}) {
    const std::string original = ReadData(name);
    ASSERT_FALSE(original.empty()) << name;
    for (int trial = 0; trial < 60; ++trial) {
      std::string s = original;
      if (trial % 10 == 9) {
        s.resize(rng() % s.size());
      } else {
        const int edits = 1 + static_cast<int>(rng() % 8);
        for (int k = 0; k < edits; ++k) s[rng() % s.size()] = alphabet[rng() % alphabet.size()];
      }
      auto p = ParseSvg(s, name);
      if (p.ok()) {
        for (const Polyline& l : p->paths) {
          for (const auto& q : l.points) ASSERT_TRUE(q.allFinite()) << name << " trial " << trial;
        }
      }
    }
  }
}

}  // namespace
}  // namespace insitu::pattern
