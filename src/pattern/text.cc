// Text to marking geometry. Each line is laid out glyph by glyph in the font's own units, scaled
// to mm, aligned about x = 0, put on its baseline below the previous one, and at the end
// optionally bent onto a circle.
//
// Outline fonts. fontconfig turns the style's pattern into a font file, the same match the
// desktop makes, so "Liberation Serif:bold" means what the operator sees in a word processor.
// FreeType reads each glyph unscaled (FT_LOAD_NO_SCALE: font units, no hinting; hinting snaps
// outlines to a screen's pixel grid, and a galvo has none, so it would only move a letter's
// edges). FT_Outline_Decompose gives lines and quadratic (TrueType) or cubic (CFF) Béziers,
// flattened here by uniform steps sized from the curve's second derivative. Every contour is
// closed, and a letter's counters (the hole of 'O', 'A', 'e') are contours of their own, so the
// even-odd hatch leaves them unmarked whatever way the font winds them.
//
// Hershey fonts, from Debian's .jhf files (hershey-fonts-data): each glyph is a few open strokes on
// an integer grid (baseline at 0, capitals 21 units high in the Roman and Futura sets), marked
// once each, the way engravers, plotters and CNC software draw small text. The em of a Hershey
// font is taken as 32 units, the body its glyphs fill (the brackets of the Roman sets reach
// from -7 to 25), so that `size_is_em` means about the same size for both kinds of font.
//
// No shaping: one glyph per code point, left to right, pair kerning from the font's 'kern'
// table (FT_Get_Kerning), none from GPOS. Part marks are serial numbers, dates and names; ligatures
// and complex scripts would need HarfBuzz.
#include "insitu/pattern/text.h"

#include <ft2build.h>
#include FT_FREETYPE_H
#include FT_OUTLINE_H
#include FT_TRUETYPE_TABLES_H
#include <fontconfig/fontconfig.h>
extern "C" {
}

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "insitu/core/validate.h"
#include "pattern/flatten.h"

#ifndef INSITU_HERSHEY_FONTS_DIR
#define INSITU_HERSHEY_FONTS_DIR "/usr/share/hershey-fonts"
#endif

namespace insitu::pattern {
namespace {

constexpr std::string_view kHersheyPrefix = "hershey:";
// The most points one text may lay out: a page of 5 mm text is ~10^5.
constexpr int64_t kMaxTextPoints = 2000000;
constexpr char32_t kReplacement = 0xFFFD;
// The Hershey body: 32 units from the deepest descender to the top of the tallest glyph; the
// capitals of the Roman and Futura sets are 21 units high.
constexpr double kHersheyEmUnits = 32.0;
constexpr double kHersheyCapUnits = 21.0;
// A .jhf file holds glyphs for bytes 32..255, one line each; no glyph needs 2000 vertices.
constexpr int kHersheyMaxGlyphs = 256 - 32;
constexpr size_t kHersheyMaxLine = 4000;
// A curve is never cut into more pieces than this, whatever the tolerance asked (a metre-high
// letter at 5 um needs a few hundred).
constexpr int kMaxPiecesPerCurve = 4096;

bool IsHershey(const std::string& font) { return font.rfind(kHersheyPrefix, 0) == 0; }

std::string CodePointName(char32_t c) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "U+%04X", static_cast<unsigned>(c));
  return buf;
}

// Code points of `s`. A byte that does not begin a well-formed sequence (Unicode 15 §3.9,
// Table 3-7: no overlong forms, no surrogates, nothing above U+10FFFF), and each maximal part
// of a sequence cut short, becomes one U+FFFD (the practice §3.9 recommends, as browsers do).
std::vector<char32_t> DecodeUtf8(const std::string& s, int* invalid) {
  std::vector<char32_t> out;
  out.reserve(s.size());
  *invalid = 0;
  size_t i = 0;
  while (i < s.size()) {
    const auto b0 = static_cast<unsigned char>(s[i]);
    if (b0 < 0x80) {
      out.push_back(b0);
      ++i;
      continue;
    }
    int more = 0;
    unsigned char lo = 0x80, hi = 0xBF;  // the allowed range of the second byte
    char32_t cp = 0;
    if (b0 >= 0xC2 && b0 <= 0xDF) {
      more = 1;
      cp = b0 & 0x1F;
    } else if (b0 >= 0xE0 && b0 <= 0xEF) {
      more = 2;
      cp = b0 & 0x0F;
      if (b0 == 0xE0) lo = 0xA0;  // overlong below U+0800
      if (b0 == 0xED) hi = 0x9F;  // surrogates U+D800..DFFF
    } else if (b0 >= 0xF0 && b0 <= 0xF4) {
      more = 3;
      cp = b0 & 0x07;
      if (b0 == 0xF0) lo = 0x90;  // overlong below U+10000
      if (b0 == 0xF4) hi = 0x8F;  // above U+10FFFF
    } else {
      out.push_back(kReplacement);
      ++*invalid;
      ++i;
      continue;
    }
    size_t j = i + 1;
    bool ok = true;
    for (int k = 0; k < more; ++k, ++j) {
      const unsigned char b = j < s.size() ? static_cast<unsigned char>(s[j]) : 0;
      const bool in_range =
          j < s.size() && (k == 0 ? (b >= lo && b <= hi) : (b >= 0x80 && b <= 0xBF));
      if (!in_range) {
        ok = false;
        break;
      }
      cp = (cp << 6) | (b & 0x3F);
    }
    if (ok) {
      out.push_back(cp);
    } else {
      out.push_back(kReplacement);
      ++*invalid;
    }
    i = j;  // past the sequence, or onto the byte that broke it
  }
  return out;
}

// Lines of code points split at line breaks ("\n", "\r\n" or a lone "\r"); a leading byte-order
// mark is dropped.
std::vector<std::vector<char32_t>> SplitLines(const std::vector<char32_t>& text) {
  std::vector<std::vector<char32_t>> lines(1);
  for (size_t i = 0; i < text.size(); ++i) {
    const char32_t c = text[i];
    if (i == 0 && c == 0xFEFF) continue;
    if (c == U'\r' && i + 1 < text.size() && text[i + 1] == U'\n') continue;
    if (c == U'\n' || c == U'\r') {
      lines.emplace_back();
      continue;
    }
    lines.back().push_back(c);
  }
  return lines;
}

// A glyph in font units: pen at the origin, baseline y = 0, y up.
struct Glyph {
  bool found = false;
  unsigned index = 0;  // the font's glyph index, for kerning
  std::vector<Polyline> contours;
  double advance = 0.0;
};

class Font {
 public:
  virtual ~Font() = default;
  // The glyph for `c`, curves flattened to within `tolerance` font units; found = false when the
  // font has none.
  virtual Glyph Load(char32_t c, double tolerance) = 0;
  // Pair kerning (font units) between `left` and the `right` drawn after it.
  virtual double Kerning(const Glyph& left, const Glyph& right) = 0;
  double cap_height = 0.0;  // font units
  double em = 0.0;          // font units
  std::string name;         // as warnings name it
};

// Uniform parameter steps for a Bézier whose second derivative is at most `b2` (font units):
// a chord over a parameter step h departs from the curve by at most h^2 b2 / 8.
int BezierPieces(double b2, double tolerance) {
  const double n = std::ceil(std::sqrt(b2 / (8.0 * tolerance)));
  return std::clamp(static_cast<int>(std::min(n, 1e9)), 1, kMaxPiecesPerCurve);
}

struct OutlineSink {
  std::vector<Polyline>* contours;
  Eigen::Vector2d pen = Eigen::Vector2d::Zero();
  double tolerance = 1.0;

  void Add(const Eigen::Vector2d& p) {
    if (contours->empty()) contours->emplace_back();
    contours->back().points.push_back(p);
    pen = p;
  }
};

Eigen::Vector2d ToVector(const FT_Vector* v) {
  return {static_cast<double>(v->x), static_cast<double>(v->y)};
}

int MoveTo(const FT_Vector* to, void* user) {
  auto* sink = static_cast<OutlineSink*>(user);
  sink->contours->emplace_back();
  sink->Add(ToVector(to));
  return 0;
}

int LineTo(const FT_Vector* to, void* user) {
  static_cast<OutlineSink*>(user)->Add(ToVector(to));
  return 0;
}

// B''(t) = 2 (p0 - 2 p1 + p2), constant.
int ConicTo(const FT_Vector* control, const FT_Vector* to, void* user) {
  auto* sink = static_cast<OutlineSink*>(user);
  const Eigen::Vector2d p0 = sink->pen, p1 = ToVector(control), p2 = ToVector(to);
  const int n = BezierPieces(2.0 * (p0 - 2.0 * p1 + p2).norm(), sink->tolerance);
  for (int k = 1; k <= n; ++k) {
    const double t = static_cast<double>(k) / n, u = 1.0 - t;
    sink->Add(u * u * p0 + 2.0 * u * t * p1 + t * t * p2);
  }
  return 0;
}

// B''(t) = 6 ((1 - t) (p0 - 2 p1 + p2) + t (p1 - 2 p2 + p3)), largest at an end.
int CubicTo(const FT_Vector* c1, const FT_Vector* c2, const FT_Vector* to, void* user) {
  auto* sink = static_cast<OutlineSink*>(user);
  const Eigen::Vector2d p0 = sink->pen, p1 = ToVector(c1), p2 = ToVector(c2), p3 = ToVector(to);
  const double b2 = 6.0 * std::max((p0 - 2.0 * p1 + p2).norm(), (p1 - 2.0 * p2 + p3).norm());
  const int n = BezierPieces(b2, sink->tolerance);
  for (int k = 1; k <= n; ++k) {
    const double t = static_cast<double>(k) / n, u = 1.0 - t;
    sink->Add(u * u * u * p0 + 3.0 * u * u * t * p1 + 3.0 * u * t * t * p2 + t * t * t * p3);
  }
  return 0;
}

// FreeType ends each contour on its first point; the polyline closes itself instead. Repeated
// points (a curve's end on the next line's start) are dropped, and so are contours too small to
// enclose anything.
void CloseContours(std::vector<Polyline>* contours) {
  std::vector<Polyline> kept;
  for (Polyline& c : *contours) {
    std::vector<Eigen::Vector2d> pts;
    for (const Eigen::Vector2d& p : c.points) {
      if (pts.empty() || (p - pts.back()).norm() > 1e-9) pts.push_back(p);
    }
    while (pts.size() > 1 && (pts.front() - pts.back()).norm() <= 1e-9) pts.pop_back();
    if (pts.size() < 3) continue;
    kept.push_back({std::move(pts), true});
  }
  *contours = std::move(kept);
}

struct FtLibraryDeleter {
  void operator()(FT_Library l) const { FT_Done_FreeType(l); }
};
struct FtFaceDeleter {
  void operator()(FT_Face f) const { FT_Done_Face(f); }
};
struct FcPatternDeleter {
  void operator()(FcPattern* p) const { FcPatternDestroy(p); }
};
using FcPatternPtr = std::unique_ptr<FcPattern, FcPatternDeleter>;

struct MatchedFont {
  std::string file;
  int index = 0;
  std::string family;
  std::string style;
};

// Family names compare as fontconfig compares them: case and blanks do not count.
bool SameFamily(std::string_view a, std::string_view b) {
  auto folded = [](std::string_view s) {
    std::string out;
    for (const char c : s) {
      if (c != ' ') out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
    return out;
  };
  return folded(a) == folded(b);
}

// Names that stand for whichever font the system prefers; their match is not a substitution.
bool IsGenericFamily(const std::string& family) {
  static const char* const kGeneric[] = {"sans-serif", "sans",    "serif",     "monospace", "mono",
                                         "cursive",    "fantasy", "system-ui", "emoji",     "math"};
  for (const char* g : kGeneric) {
    if (SameFamily(family, g)) return true;
  }
  return false;
}

Result<MatchedFont> MatchFont(const std::string& spec, std::vector<std::string>* warnings) {
  if (!FcInit()) {
    return NotFound("font '" + spec + "': fontconfig could not load its configuration");
  }
  FcPatternPtr pattern(FcNameParse(reinterpret_cast<const FcChar8*>(spec.c_str())));
  if (!pattern) {
    return InvalidArgument("font '" + spec +
                           "' is not a fontconfig pattern (\"Family\", \"Family:bold\", ...)");
  }
  std::string asked;
  FcChar8* s = nullptr;
  if (FcPatternGetString(pattern.get(), FC_FAMILY, 0, &s) == FcResultMatch) {
    asked = reinterpret_cast<const char*>(s);
  }
  // Outlines are what a laser can follow: prefer them over bitmap fonts of the same name.
  FcBool b;
  if (FcPatternGetBool(pattern.get(), FC_OUTLINE, 0, &b) != FcResultMatch) {
    FcPatternAddBool(pattern.get(), FC_OUTLINE, FcTrue);
  }
  FcConfigSubstitute(nullptr, pattern.get(), FcMatchPattern);
  FcDefaultSubstitute(pattern.get());
  FcResult result = FcResultNoMatch;
  FcPatternPtr match(FcFontMatch(nullptr, pattern.get(), &result));
  if (!match) {
    return NotFound("font '" + spec +
                    "': fontconfig knows no font at all (install fonts-dejavu-core)");
  }
  MatchedFont m;
  if (FcPatternGetString(match.get(), FC_FILE, 0, &s) != FcResultMatch) {
    return NotFound("font '" + spec + "': fontconfig's match has no file");
  }
  m.file = reinterpret_cast<const char*>(s);
  if (FcPatternGetInteger(match.get(), FC_INDEX, 0, &m.index) != FcResultMatch) m.index = 0;
  if (FcPatternGetString(match.get(), FC_STYLE, 0, &s) == FcResultMatch) {
    m.style = reinterpret_cast<const char*>(s);
  }
  // A font may carry its family in several languages; any of them counts as the one asked for.
  bool same = asked.empty() || IsGenericFamily(asked);
  for (int i = 0; FcPatternGetString(match.get(), FC_FAMILY, i, &s) == FcResultMatch; ++i) {
    if (i == 0) m.family = reinterpret_cast<const char*>(s);
    if (!asked.empty() && SameFamily(reinterpret_cast<const char*>(s), asked)) {
      same = true;
    }
  }
  if (!same) {
    warnings->push_back("text: font family '" + asked + "' is not installed; drawn with '" +
                        m.family + "' (" + m.style + ", " + m.file + ") instead");
  }
  return m;
}

class OutlineFont final : public Font {
 public:
  static Result<std::unique_ptr<Font>> Open(const std::string& spec,
                                            std::vector<std::string>* warnings) {
    INSITU_ASSIGN_OR_RETURN(MatchedFont m, MatchFont(spec, warnings));
    auto font = std::unique_ptr<OutlineFont>(new OutlineFont);
    FT_Library library = nullptr;
    if (FT_Init_FreeType(&library) != 0) return Internal("text: FreeType did not start");
    font->library_.reset(library);
    FT_Face face = nullptr;
    if (const FT_Error e = FT_New_Face(library, m.file.c_str(), m.index, &face); e != 0) {
      return NotFound("font '" + spec + "': FreeType cannot read " + m.file + " (error " +
                      std::to_string(e) + ")");
    }
    font->face_.reset(face);
    if (!FT_IS_SCALABLE(face) || face->units_per_EM == 0) {
      return NotFound("font '" + spec + "': " + m.file + " has no outlines to mark");
    }
    if (face->charmap == nullptr) FT_Select_Charmap(face, FT_ENCODING_UNICODE);
    font->name = m.family + (m.style.empty() ? "" : " " + m.style);
    font->em = face->units_per_EM;
    // The cap height the type designer declared (OS/2 version 2 and later), else the top of
    // 'H' (flat-topped, so its outline's top is the cap height without overshoot).
    const auto* os2 = static_cast<const TT_OS2*>(FT_Get_Sfnt_Table(face, FT_SFNT_OS2));
    if (os2 != nullptr && os2->version >= 2 && os2->version != 0xFFFF && os2->sCapHeight > 0) {
      font->cap_height = os2->sCapHeight;
    } else if (const FT_UInt h = FT_Get_Char_Index(face, 'H');
               h != 0 && FT_Load_Glyph(face, h, FT_LOAD_NO_SCALE) == 0 &&
               face->glyph->format == FT_GLYPH_FORMAT_OUTLINE) {
      FT_BBox box;
      FT_Outline_Get_CBox(&face->glyph->outline, &box);
      font->cap_height = static_cast<double>(box.yMax);
    }
    if (!(font->cap_height > 0)) {
      font->cap_height = 0.7 * font->em;
      warnings->push_back("text: " + font->name +
                          " declares no cap height and has no 'H'; cap height taken as 0.7 em");
    }
    return std::unique_ptr<Font>(std::move(font));
  }

  Glyph Load(char32_t c, double tolerance) override {
    Glyph g;
    FT_Face face = face_.get();
    g.index = FT_Get_Char_Index(face, c);
    if (g.index == 0) return g;
    if (FT_Load_Glyph(face, g.index, FT_LOAD_NO_SCALE) != 0 ||
        face->glyph->format != FT_GLYPH_FORMAT_OUTLINE) {
      return g;
    }
    g.found = true;
    g.advance = static_cast<double>(face->glyph->metrics.horiAdvance);
    OutlineSink sink{&g.contours, Eigen::Vector2d::Zero(), tolerance};
    FT_Outline_Funcs funcs{};
    funcs.move_to = MoveTo;
    funcs.line_to = LineTo;
    funcs.conic_to = ConicTo;
    funcs.cubic_to = CubicTo;
    if (FT_Outline_Decompose(&face->glyph->outline, &funcs, &sink) != 0) g.contours.clear();
    CloseContours(&g.contours);
    return g;
  }

  double Kerning(const Glyph& left, const Glyph& right) override {
    if (!FT_HAS_KERNING(face_.get())) return 0.0;
    FT_Vector k{0, 0};
    if (FT_Get_Kerning(face_.get(), left.index, right.index, FT_KERNING_UNSCALED, &k) != 0) {
      return 0.0;
    }
    return static_cast<double>(k.x);
  }

 private:
  OutlineFont() = default;
  // Declared first so that it outlives the face made from it.
  std::unique_ptr<std::remove_pointer_t<FT_Library>, FtLibraryDeleter> library_;
  std::unique_ptr<std::remove_pointer_t<FT_Face>, FtFaceDeleter> face_;
};

std::string HersheyDir() {
  const char* env = std::getenv("HERSHEY_FONTS_DIR");  // as libhersheyfont reads it
  return env != nullptr && *env != '\0' ? env : INSITU_HERSHEY_FONTS_DIR;
}

std::string HersheyNamesIn(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".jhf") names.push_back(e.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

// Refuses a file that is not a .jhf font: more glyphs than bytes 32..255, overlong lines, a
// vertex count that does not match the line, a left edge right of the right edge.
Status CheckJhf(const std::string& text, const std::string& path) {
  if (text.find('\0') != std::string::npos) return ParseError(path + ": not a Hershey font file");
  std::istringstream in(text);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    const std::string where = path + ": line " + std::to_string(n) + ": ";
    if (n > kHersheyMaxGlyphs) {
      return ParseError(where + "more than " + std::to_string(kHersheyMaxGlyphs) + " glyphs");
    }
    if (line.size() < 10 || line.size() > kHersheyMaxLine) {
      return ParseError(where + "a glyph line is 10 to " + std::to_string(kHersheyMaxLine) +
                        " characters long");
    }
    const std::string count = line.substr(5, 3);
    const size_t first = count.find_first_not_of(' ');
    if (first == std::string::npos ||
        count.find_first_not_of("0123456789", first) != std::string::npos ||
        2 * std::stoul(count.substr(first)) != line.size() - 8) {
      return ParseError(where + "the vertex count does not match the line");
    }
    if (line[8] > line[9]) return ParseError(where + "left edge right of the right edge");
  }
  if (n == 0) return ParseError(path + ": empty Hershey font file");
  return Status::Ok();
}

class HersheyFont final : public Font {
 public:
  static Result<std::unique_ptr<Font>> Open(const std::string& spec) {
    const std::string name = spec.substr(kHersheyPrefix.size());
    const std::string dir = HersheyDir();
    const std::string path = dir + "/" + name + ".jhf";
    auto text = ReadPatternFile(path, "Hershey font");
    if (!text.ok()) {
      const std::string have = HersheyNamesIn(dir);
      return NotFound("font '" + spec + "': no " + path + " (" +
                      (have.empty() ? "no Hershey fonts there; install hershey-fonts-data"
                                    : "installed: " + have) +
                      ")");
    }
    INSITU_RETURN_IF_ERROR(CheckJhf(*text, path));
    auto font = std::unique_ptr<HersheyFont>(new HersheyFont);
    font->Parse(*text);
    font->name = spec;
    font->em = kHersheyEmUnits;
    double top = 0.0;
    if (font->glyphs_.size() > 'H' - 32) {
      for (const auto& stroke : font->glyphs_['H' - 32].strokes) {
        for (const Eigen::Vector2d& p : stroke) top = std::max(top, p.y());
      }
    }
    font->cap_height = top > 0 ? top : kHersheyCapUnits;
    return std::unique_ptr<Font>(std::move(font));
  }

  Glyph Load(char32_t c, double) override {
    Glyph g;
    if (c < 32 || c - 32 >= glyphs_.size()) return g;
    const HersheyGlyph& hg = glyphs_[c - 32];
    if (hg.width <= 0) return g;  // an empty slot: the file has no glyph for this byte
    g.found = true;
    g.index = c;
    g.advance = hg.width;
    for (const auto& points : hg.strokes) {
      if (points.size() < 2) continue;
      Polyline stroke;
      stroke.points = points;
      g.contours.push_back(std::move(stroke));
    }
    return g;
  }

  double Kerning(const Glyph&, const Glyph&) override { return 0.0; }

 private:
  // One glyph of a .jhf file: its advance and strokes, x from its left edge, y up from the
  // baseline, in the font's grid units.
  struct HersheyGlyph {
    double width = 0.0;
    std::vector<std::vector<Eigen::Vector2d>> strokes;
  };
  HersheyFont() = default;

  // The .jhf format (James Hurt's): one glyph per line, for bytes 32 up, each a 5-character
  // number, a 3-character count of coordinate pairs, then the pairs as letters offset from
  // 'R': first the left and right edges, then the vertices, " R" lifting the pen. y grows
  // downwards with the baseline at +9. Read here rather than through libhersheyfont, which is
  // GPL-2+ and would make insitu GPL (the fonts' data has its own permissive licence). The
  // file has passed CheckJhf: every line holds its count's pairs.
  void Parse(const std::string& text) {
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
      HersheyGlyph g;
      const int left = line[8] - 'R', right = line[9] - 'R';
      g.width = right - left;
      std::vector<Eigen::Vector2d> stroke;
      for (size_t i = 10; i + 1 < line.size(); i += 2) {
        if (line[i] == ' ' && line[i + 1] == 'R') {
          if (!stroke.empty()) g.strokes.push_back(std::move(stroke));
          stroke.clear();
          continue;
        }
        stroke.emplace_back((line[i] - 'R') - left, 9.0 - (line[i + 1] - 'R'));
      }
      if (!stroke.empty()) g.strokes.push_back(std::move(stroke));
      glyphs_.push_back(std::move(g));
    }
  }

  std::vector<HersheyGlyph> glyphs_;  // bytes 32 up
};

// The baseline bent onto the circle of TextStyle::arc_radius_mm: x becomes arc length along the
// baseline, y distance from it (outwards for a positive radius, towards the centre for a
// negative one), so a glyph keeps its size at the baseline and fans out or in above it.
Eigen::Vector2d OnArc(const Eigen::Vector2d& p, double radius) {
  if (radius > 0) {
    const double theta = p.x() / radius, r = radius + p.y();
    return {r * std::sin(theta), r * std::cos(theta) - radius};
  }
  const double big_r = -radius, theta = p.x() / big_r, r = big_r - p.y();
  return {r * std::sin(theta), big_r - r * std::cos(theta)};
}

// A straight edge becomes a piece of spiral on the arc; it is cut so that each piece's chord
// stays within `tolerance` of it (the sagitta of the arc at the edge's outer radius).
Polyline BendOntoArc(const Polyline& line, double radius, double tolerance) {
  const double big_r = std::abs(radius);
  Polyline out;
  out.closed = line.closed;
  const size_t n = line.points.size();
  if (n < 2) {
    for (const Eigen::Vector2d& a : line.points) out.points.push_back(OnArc(a, radius));
    return out;
  }
  const size_t edges = line.closed ? n : n - 1;
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Vector2d& a = line.points[k];
    out.points.push_back(OnArc(a, radius));
    if (k >= edges) continue;
    const Eigen::Vector2d& b = line.points[(k + 1) % n];
    const double r_out = big_r + std::max(std::abs(a.y()), std::abs(b.y()));
    const int pieces = std::min(ArcChords(r_out, std::abs(b.x() - a.x()) / big_r, tolerance, 1),
                                kMaxPiecesPerCurve);
    for (int m = 1; m < pieces; ++m) {
      out.points.push_back(OnArc(a + (b - a) * (static_cast<double>(m) / pieces), radius));
    }
  }
  return out;
}

std::string Mm(double v) {
  std::ostringstream os;
  os << v << " mm";
  return os.str();
}

}  // namespace

Status TextStyle::Validate() const {
  if (font.empty()) return InvalidArgument("font must name a font family or hershey:NAME, got ''");
  if (IsHershey(font)) {
    const std::string name = font.substr(kHersheyPrefix.size());
    if (name.empty() ||
        name.find_first_not_of("abcdefghijklmnopqrstuvwxyz"
                               "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos) {
      return InvalidArgument(
          "font must be hershey:NAME with NAME of letters, digits, '_' or '-' "
          "(hershey:rowmans, hershey:futural, ...), got '" +
          font + "'");
    }
  }
  if (!IsPositiveFinite(height_mm)) return InvalidValue("height_mm", "> 0 and finite", height_mm);
  if (!std::isfinite(letter_spacing_mm)) {
    return InvalidValue("letter_spacing_mm", "finite", letter_spacing_mm);
  }
  if (!IsPositiveFinite(line_spacing)) {
    return InvalidValue("line_spacing", "> 0 and finite", line_spacing);
  }
  if (!std::isfinite(arc_radius_mm)) return InvalidValue("arc_radius_mm", "finite", arc_radius_mm);
  // Below the letter height the tops (outside) or the letters themselves (inside) would reach
  // the centre and fold over.
  if (arc_radius_mm != 0.0 && !(std::abs(arc_radius_mm) > height_mm)) {
    return InvalidValue("arc_radius_mm",
                        "0 (straight) or larger in size than height_mm (" + Mm(height_mm) + ")",
                        arc_radius_mm);
  }
  return Status::Ok();
}

Result<VectorPattern> RenderText(const std::string& utf8, const TextStyle& style,
                                 double tolerance_mm) {
  INSITU_RETURN_IF_ERROR(style.Validate());
  if (!IsPositiveFinite(tolerance_mm)) {
    return InvalidValue("tolerance_mm", "> 0 and finite", tolerance_mm);
  }
  if (utf8.empty()) return InvalidArgument("text is empty");

  VectorPattern out;
  out.units = "mm";
  std::unique_ptr<Font> font;
  if (IsHershey(style.font)) {
    INSITU_ASSIGN_OR_RETURN(font, HersheyFont::Open(style.font));
  } else {
    INSITU_ASSIGN_OR_RETURN(font, OutlineFont::Open(style.font, &out.warnings));
  }
  const double mm_per_unit = style.height_mm / (style.size_is_em ? font->em : font->cap_height);
  const double em_mm = font->em * mm_per_unit;
  const bool bend = style.arc_radius_mm != 0.0;
  // The tolerance is shared between flattening the curves and bending the baseline.
  // No finer than 1e-4 em: far below any mark's spot on any size of text, and a bound on the
  // chords a curve can take however small the tolerance asked for.
  const double flatten_units =
      std::max((bend ? 0.5 : 1.0) * tolerance_mm / mm_per_unit, 1e-4 * font->em);

  int invalid = 0;
  const std::vector<std::vector<char32_t>> lines = SplitLines(DecodeUtf8(utf8, &invalid));
  if (invalid > 0) {
    out.warnings.push_back("text: " + std::to_string(invalid) +
                           " byte sequence(s) are not UTF-8; each is drawn as U+FFFD");
  }

  std::map<char32_t, Glyph> glyphs;
  std::vector<char32_t> missing;  // distinct, in order of appearance
  int missing_count = 0, drawn = 0;
  std::vector<double> widths;
  // A text from a file may be long: its points are counted as they are laid out, and a text
  // beyond kMaxTextPoints is refused before it takes the memory (a drawing's own limit is 5 M).
  int64_t points = 0;
  for (size_t i = 0; i < lines.size(); ++i) {
    std::vector<Polyline> paths;
    double pen = 0.0;  // mm
    const Glyph* previous = nullptr;
    for (const char32_t c : lines[i]) {
      auto it = glyphs.find(c);
      if (it == glyphs.end()) it = glyphs.emplace(c, font->Load(c, flatten_units)).first;
      const Glyph& g = it->second;
      if (!g.found) {
        ++missing_count;
        if (std::find(missing.begin(), missing.end(), c) == missing.end()) missing.push_back(c);
        continue;
      }
      if (previous != nullptr) {
        pen += style.letter_spacing_mm + font->Kerning(*previous, g) * mm_per_unit;
      }
      for (const Polyline& contour : g.contours) points += static_cast<int64_t>(contour.points.size());
      if (points > kMaxTextPoints) {
        return OutOfRange("text: more than " + std::to_string(kMaxTextPoints) +
                          " outline points (" + std::to_string(utf8.size()) +
                          " bytes of text): split it, or use a coarser tolerance");
      }
      for (const Polyline& contour : g.contours) {
        Polyline p;
        p.closed = contour.closed;
        p.points.reserve(contour.points.size());
        for (const Eigen::Vector2d& q : contour.points) {
          p.points.emplace_back(pen + q.x() * mm_per_unit, q.y() * mm_per_unit);
        }
        paths.push_back(std::move(p));
      }
      if (!g.contours.empty()) ++drawn;
      pen += g.advance * mm_per_unit;
      previous = &g;
    }
    const double shift = style.align == TextAlign::kCenter  ? -0.5 * pen
                         : style.align == TextAlign::kRight ? -pen
                                                            : 0.0;
    const double baseline = -static_cast<double>(i) * style.line_spacing * em_mm;
    for (Polyline& p : paths) {
      for (Eigen::Vector2d& q : p.points) q += Eigen::Vector2d(shift, baseline);
      out.paths.push_back(std::move(p));
    }
    widths.push_back(pen);
  }

  if (missing_count > 0) {
    out.skipped["missing_glyph"] += missing_count;
    std::string list;
    for (size_t k = 0; k < missing.size() && k < 8; ++k) {
      list += (k ? ", " : "") + CodePointName(missing[k]);
    }
    if (missing.size() > 8) list += ", ...";
    out.warnings.push_back("text: " + std::to_string(missing_count) +
                           " character(s) have no glyph in " + font->name + " and are left out (" +
                           list + ")");
  }

  if (bend) {
    const double big_r = std::abs(style.arc_radius_mm);
    // The deepest reach towards the centre: below the baseline outside the circle, above it
    // inside.
    double reach = 0.0;
    for (const Polyline& p : out.paths) {
      for (const Eigen::Vector2d& q : p.points) {
        reach = std::max(reach, style.arc_radius_mm > 0 ? -q.y() : q.y());
      }
    }
    if (!(reach < big_r)) {
      return InvalidArgument("arc_radius_mm " + Mm(style.arc_radius_mm) +
                             " is too small: the text reaches " + Mm(reach) +
                             " from the first baseline towards the centre");
    }
    const double circumference = 2.0 * std::numbers::pi * big_r;
    for (size_t i = 0; i < widths.size(); ++i) {
      if (widths[i] > circumference) {
        out.warnings.push_back("text: line " + std::to_string(i + 1) + " (" + Mm(widths[i]) +
                               ") is longer than the circle of arc_radius_mm (" +
                               Mm(circumference) + "); its ends overlap");
      }
    }
    for (Polyline& p : out.paths) p = BendOntoArc(p, style.arc_radius_mm, 0.5 * tolerance_mm);
  }

  out.texts = 1;
  out.converted["glyph"] = drawn;
  return out;
}

}  // namespace insitu::pattern
