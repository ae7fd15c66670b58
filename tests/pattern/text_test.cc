// Text as marking geometry, measured against the fonts Debian ships (fonts-dejavu-core,
// hershey-fonts-data): cap height, advances and kerning, the counter of an 'O' left unhatched,
// Hershey strokes, alignment, line spacing, the arc, substitution and missing-glyph warnings,
// malformed UTF-8 and refused styles.
//
// Sizes: 0.5 % of a 5 mm letter is 25 um, about the radius of a fibre laser's focused spot, so a
// size error within it cannot be seen in the mark. Positions that are pure arithmetic on the
// font's numbers (advances, shifts, baselines) are held to 1e-9 mm.
#include "insitu/pattern/text.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace insitu::pattern {
namespace {

// DejaVu Sans (2.37, Debian 12), in its 2048 units per em: 'H' is 1493 units high (flat top,
// the cap height), 1540 wide in advance with 201 units of side bearing on either side; the
// 'kern' table moves V 131 units towards A.
constexpr double kDejaVuEm = 2048, kDejaVuCap = 1493, kDejaVuAdvanceH = 1540, kDejaVuBearingH = 201,
                 kDejaVuKernAV = -131;
constexpr double kSizeTolerance = 0.005;  // relative; see the file comment
constexpr double kExact = 1e-9;           // mm

struct Box {
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  double Width() const { return xmax - xmin; }
  double Height() const { return ymax - ymin; }
};

Box Bounds(const std::vector<Polyline>& paths) {
  Box b;
  for (const Polyline& p : paths) {
    for (const Eigen::Vector2d& q : p.points) {
      b.xmin = std::min(b.xmin, q.x());
      b.xmax = std::max(b.xmax, q.x());
      b.ymin = std::min(b.ymin, q.y());
      b.ymax = std::max(b.ymax, q.y());
    }
  }
  return b;
}

// The paths lying between two heights: one line of a multi-line text.
std::vector<Polyline> Between(const VectorPattern& p, double ymin, double ymax) {
  std::vector<Polyline> out;
  for (const Polyline& path : p.paths) {
    const Box b = Bounds({path});
    if (b.ymin >= ymin && b.ymax <= ymax) out.push_back(path);
  }
  return out;
}

VectorPattern Render(const std::string& text, const TextStyle& style, double tolerance = 0.005) {
  auto r = RenderText(text, style, tolerance);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return r.ok() ? std::move(r).value() : VectorPattern{};
}

bool AnyWarningHas(const VectorPattern& p, const std::string& needle) {
  return std::any_of(p.warnings.begin(), p.warnings.end(),
                     [&](const std::string& w) { return w.find(needle) != std::string::npos; });
}

double DistanceToSegment(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                         const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double t =
      ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

TEST(Text, CapHeightOfDejaVuSansH) {
  TextStyle style;  // DejaVu Sans, 5 mm cap height
  const VectorPattern h = Render("H", style);
  ASSERT_EQ(h.paths.size(), 1u);  // 'H' is one contour
  EXPECT_TRUE(h.paths[0].closed);
  const Box b = Bounds(h.paths);
  EXPECT_NEAR(b.ymin, 0.0, kExact);  // standing on the baseline
  EXPECT_NEAR(b.Height(), 5.0, 5.0 * kSizeTolerance);
  EXPECT_EQ(h.texts, 1);
  EXPECT_EQ(h.converted.at("glyph"), 1);
  EXPECT_TRUE(h.warnings.empty()) << h.warnings.front();
  EXPECT_EQ(h.units, "mm");

  // As an em size (CSS font-size) the same 5 mm makes a smaller capital: 1493/2048 of it.
  style.size_is_em = true;
  const double cap = 5.0 * kDejaVuCap / kDejaVuEm;
  EXPECT_NEAR(Bounds(Render("H", style).paths).Height(), cap, cap * kSizeTolerance);
}

// Advances, letter spacing and alignment: a right-aligned line ends at x = 0, so the shift
// between left and right alignment of "H" is H's advance; "HH" is two of them plus the spacing,
// and centring moves a line by half its width.
TEST(Text, AdvanceLetterSpacingAndAlignment) {
  TextStyle style;
  const Box left = Bounds(Render("H", style).paths);
  style.align = TextAlign::kRight;
  const double advance = left.xmax - Bounds(Render("H", style).paths).xmax;
  const double expected_advance = 5.0 * kDejaVuAdvanceH / kDejaVuCap;
  EXPECT_NEAR(advance, expected_advance, expected_advance * kSizeTolerance);

  style.align = TextAlign::kLeft;
  style.letter_spacing_mm = 0.3;
  const Box hh = Bounds(Render("HH", style).paths);
  EXPECT_NEAR(hh.xmax - left.xmax, advance + 0.3, kExact);  // H-H has no kerning pair
  EXPECT_NEAR(hh.xmin, left.xmin, kExact);

  const double width = 2 * advance + 0.3;
  style.align = TextAlign::kCenter;
  const Box centred = Bounds(Render("HH", style).paths);
  EXPECT_NEAR(centred.xmin, hh.xmin - width / 2, kExact);
  EXPECT_NEAR(centred.ymin, hh.ymin, kExact);
  style.align = TextAlign::kRight;
  EXPECT_NEAR(Bounds(Render("HH", style).paths).xmin, hh.xmin - width, kExact);
}

// Each line is aligned on its own: DejaVu's H has equal side bearings, so centred lines of any
// number of H's are symmetric about x = 0 and right-aligned ones end one bearing short of it.
TEST(Text, EachLineIsAlignedOnItsOwn) {
  TextStyle style;
  style.align = TextAlign::kCenter;
  const VectorPattern centred = Render("HHHH\nH", style);
  const Box first = Bounds(Between(centred, -1, 10)), second = Bounds(Between(centred, -10, -1));
  EXPECT_NEAR(first.xmin + first.xmax, 0.0, kExact);
  EXPECT_NEAR(second.xmin + second.xmax, 0.0, kExact);
  EXPECT_GT(first.Width(), 3 * second.Width());  // the two lines really are told apart

  style.align = TextAlign::kRight;
  const VectorPattern right = Render("HHHH\nH", style);
  const double bearing = 5.0 * kDejaVuBearingH / kDejaVuCap;
  EXPECT_NEAR(Bounds(Between(right, -1, 10)).xmax, -bearing, bearing * kSizeTolerance);
  EXPECT_NEAR(Bounds(Between(right, -10, -1)).xmax, Bounds(Between(right, -1, 10)).xmax, kExact);
}

// A kerning pair from the font's 'kern' table: V moves 131 units (0.44 mm at 5 mm) under A.
TEST(Text, KerningFromTheFont) {
  TextStyle style;
  const double v_alone = Bounds(Render("V", style).paths).xmax;
  style.align = TextAlign::kRight;
  const double a_advance =
      Bounds(Render("A", TextStyle{}).paths).xmax - Bounds(Render("A", style).paths).xmax;
  const double kern = Bounds(Render("AV", TextStyle{}).paths).xmax - v_alone - a_advance;
  const double expected = 5.0 * kDejaVuKernAV / kDejaVuCap;
  EXPECT_NEAR(kern, expected, std::abs(expected) * kSizeTolerance);
}

// 'O' is two closed contours; the even-odd hatch fills the ring and leaves the counter empty.
// The counter's half-width is about 1.7 mm at 5 mm (an O 1382 units wide with strokes of about
// 180), so no hatch line may come within 1 mm of the letter's centre, while lines through the
// centre's height must still cross both strokes.
TEST(Text, TheCounterOfOStaysUnmarked) {
  const VectorPattern o = Render("O", TextStyle{});
  ASSERT_EQ(o.paths.size(), 2u);
  EXPECT_TRUE(o.paths[0].closed);
  EXPECT_TRUE(o.paths[1].closed);
  const Box b = Bounds(o.paths);
  const Eigen::Vector2d centre(0.5 * (b.xmin + b.xmax), 0.5 * (b.ymin + b.ymax));
  constexpr double kSpacing = 0.05;
  for (double angle : {0.0, 90.0, 45.0}) {
    auto hatch = HatchPolygons(o, kSpacing, angle);
    ASSERT_TRUE(hatch.ok()) << hatch.status().ToString();
    bool before = false, after = false;
    const Eigen::Vector2d dir(std::cos(angle * std::numbers::pi / 180),
                              std::sin(angle * std::numbers::pi / 180));
    for (const Segment2& s : *hatch) {
      EXPECT_GT(DistanceToSegment(centre, s.a, s.b), 1.0) << "angle " << angle;
      if (DistanceToSegment(centre, s.a, s.b) < 1.0 + 1.0) {
        // Near the centre: a stroke's piece lies wholly before or after it along the line.
        before |= std::max((s.a - centre).dot(dir), (s.b - centre).dot(dir)) < 0;
        after |= std::min((s.a - centre).dot(dir), (s.b - centre).dot(dir)) > 0;
      }
    }
    EXPECT_TRUE(before && after) << "angle " << angle;
  }
  // The same check catches an O whose hole is lost: with only its outer contour the centre is
  // hatched.
  const bool first_is_outer = Bounds({o.paths[0]}).Width() > Bounds({o.paths[1]}).Width();
  VectorPattern solid;
  solid.paths.push_back(o.paths[first_is_outer ? 0 : 1]);
  auto filled = HatchPolygons(solid, kSpacing, 0.0);
  ASSERT_TRUE(filled.ok());
  EXPECT_TRUE(std::any_of(filled->begin(), filled->end(), [&](const Segment2& s) {
    return DistanceToSegment(centre, s.a, s.b) < kSpacing;
  }));
}

// Every vertex of the flattened outline lies on the font's curve, so a much finer flattening
// (0.5 um) stands for the curve: none of its points may be farther than the tolerance (plus the
// fine one's) from the coarse outline.
TEST(Text, CurvesAreFlattenedWithinTheTolerance) {
  constexpr double kCoarse = 0.02, kFine = 0.0005;
  const VectorPattern coarse = Render("O", TextStyle{}, kCoarse);
  const VectorPattern fine = Render("O", TextStyle{}, kFine);
  ASSERT_EQ(coarse.paths.size(), fine.paths.size());
  size_t coarse_points = 0, fine_points = 0;
  double worst = 0;
  for (size_t k = 0; k < coarse.paths.size(); ++k) {
    const auto& c = coarse.paths[k].points;
    coarse_points += c.size();
    fine_points += fine.paths[k].points.size();
    for (const Eigen::Vector2d& p : fine.paths[k].points) {
      double nearest = 1e300;
      for (size_t m = 0; m < c.size(); ++m) {
        nearest = std::min(nearest, DistanceToSegment(p, c[m], c[(m + 1) % c.size()]));
      }
      worst = std::max(worst, nearest);
    }
  }
  EXPECT_LE(worst, kCoarse + kFine);
  EXPECT_GT(worst, 0.1 * kCoarse);  // the coarse outline really is coarse
  EXPECT_GT(fine_points, 3 * coarse_points);
}

// Baselines step down by line_spacing em: with a 5 mm em and 1.2, by 6 mm; an empty line keeps
// its place.
TEST(Text, LineSpacing) {
  TextStyle style;
  style.size_is_em = true;
  const VectorPattern p = Render("H\nH\r\n\nH", style);
  EXPECT_EQ(p.converted.at("glyph"), 3);
  EXPECT_NEAR(Bounds(Between(p, -1, 10)).ymin, 0.0, kExact);
  EXPECT_NEAR(Bounds(Between(p, -7, -0.5)).ymin, -6.0, kExact);
  EXPECT_TRUE(Between(p, -12.5, -6.5).empty());  // the empty third line
  EXPECT_NEAR(Bounds(Between(p, -19, -12.5)).ymin, -18.0, kExact);

  style.line_spacing = 2.0;
  EXPECT_NEAR(Bounds(Between(Render("H\nH", style), -11, -5)).ymin, -10.0, kExact);
}

// On an arc of radius R the baseline is the circle about (0, -R): every vertex of "HHH" lies
// between R (the feet of the stems) and R + cap height (their tops), glyphs keep their place by
// arc length, and each edge that runs along the circle (a foot, the crossbar, a top) is cut
// finely enough that its chord stays within the tolerance of the circle. R = 8 mm is tight on
// purpose: the crossbar of a 5 mm H (2.5 mm) would sag 0.07 mm uncut.
TEST(Text, ArcPutsTheBaselineOnTheCircle) {
  constexpr double kR = 8.0, kTol = 0.005, kCap = 5.0;
  TextStyle style;
  style.align = TextAlign::kCenter;
  const Box straight = Bounds(Render("HHH", style).paths);
  style.arc_radius_mm = kR;
  const VectorPattern arc = Render("HHH", style, kTol);
  ASSERT_EQ(arc.paths.size(), 3u);
  const Eigen::Vector2d centre(0, -kR);
  double r_min = 1e300, r_max = 0, a_min = 1e300, a_max = -1e300;
  int along = 0;
  for (const Polyline& p : arc.paths) {
    for (size_t k = 0; k < p.points.size(); ++k) {
      const Eigen::Vector2d q = p.points[k] - centre;
      r_min = std::min(r_min, q.norm());
      r_max = std::max(r_max, q.norm());
      a_min = std::min(a_min, std::atan2(q.x(), q.y()));
      a_max = std::max(a_max, std::atan2(q.x(), q.y()));
      const Eigen::Vector2d n = p.points[(k + 1) % p.points.size()] - centre;
      if (std::abs(n.norm() - q.norm()) < kExact && (n - q).norm() > 1e-6) {
        ++along;
        EXPECT_GE((0.5 * (q + n)).norm(), q.norm() - kTol);
      }
    }
  }
  EXPECT_NEAR(r_min, kR, kExact);
  EXPECT_NEAR(r_max, kR + kCap, kCap * kSizeTolerance);
  EXPECT_NEAR(a_min, straight.xmin / kR, kExact);  // arc length along the baseline = x
  EXPECT_NEAR(a_max, straight.xmax / kR, kExact);
  EXPECT_GT(along, 20);

  // Inside the circle: about (0, R), the baseline at the bottom, letters reaching inwards.
  style.arc_radius_mm = -kR;
  const Box inside = Bounds(Render("HHH", style).paths);
  double d_min = 1e300, d_max = 0;
  for (const Polyline& p : Render("HHH", style).paths) {
    for (const Eigen::Vector2d& q : p.points) {
      d_min = std::min(d_min, (q - Eigen::Vector2d(0, kR)).norm());
      d_max = std::max(d_max, (q - Eigen::Vector2d(0, kR)).norm());
    }
  }
  EXPECT_NEAR(d_max, kR, kExact);
  EXPECT_NEAR(d_min, kR - kCap, kCap * kSizeTolerance);
  EXPECT_GE(inside.ymin, -kExact);  // the origin is the circle's lowest point
  EXPECT_LT(inside.ymax, kR);

  // Three lines below the first reach 12 mm and more towards the centre of an 8 mm circle.
  style.arc_radius_mm = kR;
  const auto folded = RenderText("H\nH\nH", style);
  ASSERT_FALSE(folded.ok());
  EXPECT_EQ(folded.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(folded.status().message().find("arc_radius_mm"), std::string::npos);
}

TEST(Text, HersheyRowmansHIsThreeOpenStrokes) {
  TextStyle style;
  style.font = "hershey:rowmans";
  const VectorPattern h = Render("H", style);
  ASSERT_EQ(h.paths.size(), 3u);  // two stems and the crossbar
  for (const Polyline& p : h.paths) {
    EXPECT_FALSE(p.closed);
    EXPECT_EQ(p.points.size(), 2u);
  }
  const Box b = Bounds(h.paths);
  EXPECT_NEAR(b.ymin, 0.0, kExact);
  EXPECT_NEAR(b.Height(), 5.0, 5.0 * kSizeTolerance);
  EXPECT_EQ(h.converted.at("glyph"), 1);
  EXPECT_TRUE(h.warnings.empty());
  // Strokes only: nothing to hatch.
  EXPECT_FALSE(HatchPolygons(h, 0.05, 0).ok());

  // rowmans 'H' spans 22 grid units in advance against 21 of height.
  style.align = TextAlign::kRight;
  EXPECT_NEAR(b.xmax - Bounds(Render("H", style).paths).xmax, 5.0 * 22 / 21, kExact);

  // Only ASCII is in a Hershey file: 'é' is left out and said so.
  style.align = TextAlign::kLeft;
  const VectorPattern accent = Render("H\xc3\xa9H", style);
  EXPECT_EQ(accent.converted.at("glyph"), 2);
  EXPECT_EQ(accent.skipped.at("missing_glyph"), 1);
  EXPECT_TRUE(AnyWarningHas(accent, "U+00E9"));
  EXPECT_TRUE(AnyWarningHas(accent, "hershey:rowmans"));
}

TEST(Text, UnknownHersheyFontListsTheInstalledOnes) {
  TextStyle style;
  style.font = "hershey:nosuchfont";
  const auto r = RenderText("H", style);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find("rowmans"), std::string::npos) << r.status().message();
  style.font = "hershey:../../etc/passwd";
  EXPECT_EQ(RenderText("H", style).status().code(), StatusCode::kInvalidArgument);
}

// A damaged .jhf file is refused with the line at fault (more glyphs than bytes 32..255,
// a count that does not match its line, edges out of order).
TEST(Text, DamagedHersheyFileIsAParseError) {
  const std::string dir = ::testing::TempDir() + "/insitu_text_hershey";
  std::filesystem::create_directories(dir);
  const std::string space = "12345  1JZ\n";  // rowmans' space: no strokes, 16 units wide
  std::string many;
  for (int k = 0; k < 300; ++k) many += space;
  const std::pair<const char*, std::string> files[] = {
      {"toolong", many},                       // 300 glyphs
      {"badcount", "  508  9G]KFK[ RYFY[\n"},  // 9 vertices announced, 7 given
      {"backwards", "  508  2]GKF\n"},         // left edge right of the right one
  };
  for (const auto& [name, content] : files) std::ofstream(dir + "/" + name + ".jhf") << content;
  const char* old = std::getenv("HERSHEY_FONTS_DIR");
  const std::string saved = old ? old : "";
  setenv("HERSHEY_FONTS_DIR", dir.c_str(), 1);
  TextStyle style;
  for (const auto& [name, content] : files) {
    style.font = std::string("hershey:") + name;
    const auto r = RenderText("H", style);
    EXPECT_EQ(r.status().code(), StatusCode::kParseError) << name << ": " << r.status().ToString();
  }
  if (old) {
    setenv("HERSHEY_FONTS_DIR", saved.c_str(), 1);
  } else {
    unsetenv("HERSHEY_FONTS_DIR");
  }
  std::filesystem::remove_all(dir);
}

TEST(Text, MissingFamilyIsNamedInAWarning) {
  TextStyle style;
  style.font = "Nonexistent Family Xyz";
  const VectorPattern p = Render("H", style);
  EXPECT_EQ(p.converted.at("glyph"), 1);  // drawn with the closest match
  ASSERT_EQ(p.warnings.size(), 1u);
  EXPECT_NE(p.warnings[0].find("'Nonexistent Family Xyz'"), std::string::npos) << p.warnings[0];
  EXPECT_NE(p.warnings[0].find("instead"), std::string::npos) << p.warnings[0];

  // The family asked in another spelling, a style of it, or a generic name: no warning.
  for (const char* font : {"dejavu sans", "DejaVu Sans:bold", "sans-serif"}) {
    style.font = font;
    EXPECT_TRUE(Render("H", style).warnings.empty()) << font;
  }
}

TEST(Text, MissingGlyphIsCountedAndNamed) {
  const VectorPattern p = Render("H\xe4\xb8\xadH", TextStyle{});  // H, U+4E2D (CJK), H
  EXPECT_EQ(p.converted.at("glyph"), 2);
  EXPECT_EQ(p.skipped.at("missing_glyph"), 1);
  EXPECT_TRUE(AnyWarningHas(p, "U+4E2D"));
  EXPECT_EQ(p.paths.size(), 2u);
}

// Malformed UTF-8: each maximal invalid piece is one U+FFFD (which DejaVu Sans draws), never a
// crash: a stray byte, a lead byte without its continuation, a truncated tail, an overlong '/'
// (two bytes never valid), a surrogate (ED A0 80: three pieces), a code point past U+10FFFF.
TEST(Text, InvalidUtf8BecomesReplacementCharacters) {
  struct Case {
    std::string text;
    int replaced;
    int glyphs;
  };
  const Case cases[] = {
      {"H\xff\xc3(H\xe2\x82", 3, 6},  // stray, lead without continuation, cut short
      {"\xc0\xaf", 2, 2},             // overlong '/'
      {"\xed\xa0\x80", 3, 3},         // the surrogate U+D800
      {"\xf4\x90\x80\x80", 4, 4},     // U+110000
      {"\xe2\x82\xac", 0, 1},         // the euro sign, well-formed
  };
  for (const Case& c : cases) {
    const VectorPattern p = Render(c.text, TextStyle{});
    EXPECT_EQ(p.converted.at("glyph"), c.glyphs) << c.text;
    if (c.replaced > 0) {
      EXPECT_TRUE(AnyWarningHas(p, std::to_string(c.replaced) + " byte sequence")) << c.text;
    } else {
      EXPECT_TRUE(p.warnings.empty()) << c.text;
    }
  }
  // Random bytes (fixed seed): every string renders or is refused, in both kinds of font.
  std::mt19937_64 rng(20240611);
  TextStyle hershey;
  hershey.font = "hershey:futural";
  for (int n = 0; n < 200; ++n) {
    std::string s(1 + rng() % 24, ' ');
    for (char& ch : s) ch = static_cast<char>(rng() & 0xFF);
    EXPECT_TRUE(RenderText(s, TextStyle{}).ok()) << n;
    EXPECT_TRUE(RenderText(s, hershey).ok()) << n;
  }
}

TEST(Text, ValidateNamesTheKey) {
  auto error_of = [](TextStyle s) { return s.Validate().message(); };
  EXPECT_TRUE(TextStyle{}.Validate().ok());
  TextStyle s;
  s.height_mm = 0;
  EXPECT_EQ(error_of(s).rfind("height_mm must be", 0), 0u) << error_of(s);
  s.height_mm = std::nan("");
  EXPECT_EQ(error_of(s).rfind("height_mm", 0), 0u);
  s.height_mm = std::numeric_limits<double>::infinity();
  EXPECT_EQ(error_of(s).rfind("height_mm", 0), 0u);
  s = TextStyle{};
  s.line_spacing = 0;
  EXPECT_EQ(error_of(s).rfind("line_spacing must be", 0), 0u);
  s = TextStyle{};
  s.letter_spacing_mm = std::nan("");
  EXPECT_EQ(error_of(s).rfind("letter_spacing_mm must be", 0), 0u);
  s = TextStyle{};
  s.arc_radius_mm = std::numeric_limits<double>::infinity();
  EXPECT_EQ(error_of(s).rfind("arc_radius_mm must be", 0), 0u);
  s.arc_radius_mm = -4;  // inside a 4 mm circle a 5 mm letter reaches past the centre
  EXPECT_EQ(error_of(s).rfind("arc_radius_mm must be", 0), 0u) << error_of(s);
  s = TextStyle{};
  s.font = "";
  EXPECT_EQ(error_of(s).rfind("font must", 0), 0u);
  s.font = "hershey:";
  EXPECT_EQ(error_of(s).rfind("font must", 0), 0u);

  // RenderText refuses the same, and an empty text or tolerance.
  EXPECT_EQ(RenderText("H", s).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(RenderText("", TextStyle{}).status().code(), StatusCode::kInvalidArgument);
  const auto zero = RenderText("H", TextStyle{}, 0.0);
  EXPECT_EQ(zero.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(zero.status().message().rfind("tolerance_mm", 0), 0u);
}

}  // namespace
}  // namespace insitu::pattern
