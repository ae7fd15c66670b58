// DXF input (ASCII, R12 to R2018): the drawing's model space as marking paths in mm.
//
// The file is read once into (code, value, line) groups, stopping at the first 0/EOF (R12
// writers and file transfers leave junk after it); a file that ends without EOF is accepted
// when its ENTITIES section ended, refused (naming the last line) when it was cut inside it.
// HEADER gives $INSUNITS (mm when absent or unitless) and the text code page, TABLES the text
// styles' fonts, BLOCKS the block definitions. The ENTITIES section is then drawn through one
// recursive walk that carries a 3D affine transform (file units -> mm, block insertions, the
// entities' object coordinate systems) and projects the result on the XY plane:
//
// - OCS: ARC, CIRCLE, LWPOLYLINE, 2D POLYLINE, SOLID/TRACE, INSERT, TEXT and HATCH give their
//   points in the plane normal to their extrusion (210/220/230), whose axes come from the
//   AutoCAD arbitrary axis algorithm (Ax = Wy x N when |Nx| and |Ny| < 1/64, else Wz x N;
//   Ay = N x Ax). Extrusion (0,0,-1), which mirroring in AutoCAD produces, gives Ax = -X: the
//   entity lands mirrored in x, as the designer sees it. ELLIPSE and MTEXT are in WCS, their
//   extrusion gives the normal that turns the major axis into the minor one.
// - INSERT: block base point, scale (41..43, negative mirrors), rotation (50) about the insert's
//   OCS z, row/column arrays (70/71 counts, 44/45 spacing, rotated with the block, unscaled),
//   nested to kMaxBlockDepth, a block inserting itself is refused, and the expansion is
//   bounded (kMaxEntityVisits, kMaxPoints, kMaxArrayCopies) so a small file cannot blow up.
//   ATTRIBs after an INSERT are drawn in the INSERT's space; ATTDEFs in blocks are templates
//   (drawn only when constant). DIMENSION draws its anonymous *D block when the file has it.
// - Arcs, bulges, ellipses and splines are flattened in their own plane with the tolerance
//   divided by the largest stretch of the transform to mm, so every chord stays within
//   `tolerance_mm` of the curve after a scaled or mirrored insertion.
// - HATCH: its boundary loops (polyline loops with bulges; edge loops of lines, circular and
//   elliptic arcs, splines) become closed paths, which the job's hatch fills by the even-odd
//   rule (hatch style 1 keeps the external and outermost loops, 2 the external ones); the
//   file's own pattern lines are not drawn. A loop that repeats a closed outline the drawing
//   already has (an associative hatch over its polyline) is dropped, or the even-odd rule
//   would cancel the two and leave the area unfilled. SOLID and TRACE are filled 2D
//   quadrilaterals (arrowheads, marks) and become closed areas too.
// - Open LINE/ARC/polyline/spline chains whose ends meet form closed loops (hatchable), so an
//   outline drawn as separate segments can be filled (JoinChains; Finish says why the ends
//   must meet within 0.001 mm or 1e-6 of the drawing).
// - TEXT, MTEXT, ATTRIB through RenderText: height = cap height, width factor, oblique angle,
//   rotation, mirror flags, the 72/73 alignments with the second alignment point (aligned and
//   fit stretch between the two points), the style's font (a TrueType file name -> its family
//   for fontconfig; SHX fonts -> Hershey single strokes, the engraving convention).
//
// Nothing is dropped silently: what is drawn is counted in `converted`, what is not in
// `skipped` (meshes, 3D solids, images, viewports, points, leaders, paper space, ...), and
// anything read approximately becomes a warning. Malformed input is refused with the line.
//
// libdime (BSD, Debian libdime-dev) was measured against this reader on the test corpus and
// not taken: it draws no HATCH, SPLINE, MTEXT or DIMENSION, ignores LWPOLYLINE bulges, draws
// ELLIPSE at half size, matches block names by case, keeps paper space, refuses a missing EOF,
// and took about 1.0 s against 0.4 s here for a 14 MB drawing (docs/marking.md, "DXF reader").
#include <iconv.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <map>
#include <numeric>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "insitu/pattern/text.h"
#include "insitu/pattern/vector.h"
#include "pattern/flatten.h"

namespace insitu::pattern {
namespace {

using Eigen::Affine3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

// Bounds on what a file may ask for. Real drawings nest blocks a handful deep and hold up to a
// few hundred thousand entities; these stop a crafted or broken file from recursing or
// expanding without end (a 10-level binary nesting is already 1024 copies).
constexpr int kMaxBlockDepth = 32;
constexpr int64_t kMaxArrayCopies = 100000;    // rows x columns of one INSERT
constexpr int64_t kMaxEntityVisits = 1000000;  // entities drawn, counting each block copy

// A point's cell on a grid of `size` (mm), for finding near points without comparing all
// pairs. Coordinates are finite and bounded by the reader's range check; clamped anyway.
std::pair<int64_t, int64_t> CellOf(const Eigen::Vector2d& p, double size) {
  const auto cell = [&](double v) {
    return static_cast<int64_t>(std::clamp(std::floor(v / size), -1e15, 1e15));
  };
  return {cell(p.x()), cell(p.y())};
}
struct CellHash {
  size_t operator()(const std::pair<int64_t, int64_t>& c) const {
    return std::hash<int64_t>()(c.first * 0x9E3779B97F4A7C15ull) ^ std::hash<int64_t>()(c.second);
  }
};
constexpr int64_t kMaxPoints = 5000000;        // path vertices (80 MB)
constexpr int kMaxSplineDegree = 25;
constexpr size_t kMaxTextCache = 4096;

constexpr double kDeg = M_PI / 180.0;

struct Group {
  int code = 0;
  int line = 0;  // of the code; the value is on the next line
  bool numeric = false;
  double num = 0.0;
  std::string value;
};

// Codes whose values are numbers (DXF reference, "Group code value types").
bool NumericCode(int c) {
  return (c >= 10 && c <= 99) || (c >= 110 && c <= 149) || (c >= 160 && c <= 179) ||
         (c >= 210 && c <= 239) || (c >= 270 && c <= 289) || (c >= 370 && c <= 389) ||
         (c >= 400 && c <= 409) || (c >= 1010 && c <= 1071);
}

// The codes this reader takes numbers from: a value there that is not a number is an error.
bool CheckedCode(int c) {
  return (c >= 10 && c <= 59) || (c >= 70 && c <= 79) || (c >= 90 && c <= 99) ||
         (c >= 210 && c <= 239);
}

// An integer from a file number, clamped first: casting an out-of-range double is undefined.
int ToInt(double v) { return static_cast<int>(std::clamp(v, -1e9, 1e9)); }

std::string Trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r\n");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r\n") - a + 1);
}

std::string Upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// An entity type as a `skipped` / `converted` key: lower case, [a-z0-9_].
std::string Kind(const std::string& type) {
  std::string k;
  for (char c : type.substr(0, 40)) {
    const unsigned char u = static_cast<unsigned char>(c);
    k += std::isalnum(u) ? static_cast<char>(std::tolower(u)) : '_';
  }
  return k.empty() ? "unnamed" : k;
}

// Angles in degrees from the file, reduced before any arithmetic so that a huge value cannot
// overflow; the sweep from a to b counterclockwise in (0, 360], equal angles = full turn.
double SweepDeg(double a, double b) {
  const double s = std::fmod(std::fmod(b, 360.0) - std::fmod(a, 360.0) + 720.0, 360.0);
  return s > 0.0 ? s : 360.0;
}

double SweepRad(double a, double b) {
  const double s = std::fmod(std::fmod(b, 2 * M_PI) - std::fmod(a, 2 * M_PI) + 4 * M_PI, 2 * M_PI);
  return s > 1e-12 ? s : 2 * M_PI;
}

void AppendArc(const Vector2d& c, double r, double a0, double sweep, double tol,
               std::vector<Vector2d>* out, bool include_first) {
  const int n = ArcChords(r, sweep, tol, 2);
  for (int k = include_first ? 0 : 1; k <= n; ++k) {
    const double a = a0 + sweep * k / n;
    out->push_back(c + r * Vector2d(std::cos(a), std::sin(a)));
  }
}

// Bulge b between p and q: arc with included angle 4 atan(b), counterclockwise for b > 0.
void AppendBulge(const Vector2d& p, const Vector2d& q, double b, double tol,
                 std::vector<Vector2d>* out) {
  const double chord = (q - p).norm();
  if (!(chord > 1e-12)) return;  // a repeated vertex: nothing to draw
  if (std::abs(b) < 1e-12) {
    out->push_back(q);
    return;
  }
  const double theta = 4.0 * std::atan(b);
  const double r = chord / (2.0 * std::sin(std::abs(theta) / 2.0));
  const Vector2d mid = 0.5 * (p + q);
  const Vector2d dir = (q - p) / chord;
  const Vector2d left(-dir.y(), dir.x());
  // Centre on the left of p->q for a counterclockwise arc under 180 degrees.
  const double h = r * std::cos(theta / 2.0);
  const Vector2d c = mid + (b > 0 ? 1.0 : -1.0) * h * left;
  const double a0 = std::atan2(p.y() - c.y(), p.x() - c.x());
  AppendArc(c, r, a0, theta, tol, out, false);
  out->back() = q;  // exactly on the next vertex, so chains meet
}

std::vector<Vector2d> Bulged(const std::vector<Vector2d>& v, const std::vector<double>& bulge,
                             bool closed, double tol) {
  std::vector<Vector2d> pts;
  if (v.empty()) return pts;
  pts.push_back(v[0]);
  const size_t n = v.size();
  for (size_t k = 0; k + (closed ? 0 : 1) < n; ++k) {
    AppendBulge(v[k], v[(k + 1) % n], bulge[k], tol, &pts);
  }
  if (closed && pts.size() > 1 && (pts.back() - pts.front()).norm() < 1e-12) pts.pop_back();
  return pts;
}

std::vector<Vector3d> Lift(const std::vector<Vector2d>& pts, double z) {
  std::vector<Vector3d> out;
  out.reserve(pts.size());
  for (const Vector2d& p : pts) out.emplace_back(p.x(), p.y(), z);
  return out;
}

// The AutoCAD arbitrary axis algorithm: OCS -> WCS for extrusion n.
Eigen::Matrix3d OcsToWcs(Vector3d n) {
  if (!n.allFinite() || !(n.norm() > 1e-12)) n = Vector3d::UnitZ();
  n.normalize();
  constexpr double kLimit = 1.0 / 64.0;
  Vector3d ax = (std::abs(n.x()) < kLimit && std::abs(n.y()) < kLimit) ? Vector3d::UnitY().cross(n)
                                                                       : Vector3d::UnitZ().cross(n);
  ax.normalize();
  Eigen::Matrix3d m;
  m.col(0) = ax;
  m.col(1) = n.cross(ax).normalized();
  m.col(2) = n;
  return m;
}

Affine3d Linear(const Eigen::Matrix3d& l) {
  Affine3d a = Affine3d::Identity();
  a.linear() = l;
  return a;
}

Affine3d Translate(const Vector3d& t) { return Affine3d(Eigen::Translation3d(t)); }
Affine3d Scale(double x, double y, double z) { return Affine3d(Eigen::Scaling(x, y, z)); }
Affine3d RotZ(double rad) { return Affine3d(Eigen::AngleAxisd(rad, Vector3d::UnitZ())); }

// The largest factor by which the transform, projected on XY, stretches a length: the larger
// singular value of the top 2x3 block.
double Stretch(const Affine3d& m) {
  const Eigen::Matrix<double, 2, 3> a = m.linear().topRows<2>();
  const Eigen::Matrix2d b = a * a.transpose();
  const double tr = b(0, 0) + b(1, 1);
  const double d =
      std::sqrt(std::max(0.0, (b(0, 0) - b(1, 1)) * (b(0, 0) - b(1, 1)) + 4 * b(0, 1) * b(1, 0)));
  return std::sqrt(std::max(0.0, 0.5 * (tr + d)));
}

// $INSUNITS: mm per drawing unit, and the unit's name.
double InsUnitsToMm(int code, std::string* name) {
  struct Unit {
    int code;
    double mm;
    const char* name;
  };
  static const Unit kUnits[] = {
      {1, 25.4, "in"},     {2, 304.8, "ft"},  {3, 1609344.0, "mi"},   {4, 1.0, "mm"},
      {5, 10.0, "cm"},     {6, 1000.0, "m"},  {7, 1e6, "km"},         {8, 25.4e-6, "microinch"},
      {9, 25.4e-3, "mil"}, {10, 914.4, "yd"}, {11, 1e-7, "angstrom"}, {12, 1e-6, "nm"},
      {13, 1e-3, "um"},    {14, 100.0, "dm"},
  };
  for (const Unit& u : kUnits) {
    if (u.code == code) {
      *name = u.name;
      return u.mm;
    }
  }
  *name = "unitless (read as mm)";
  return 1.0;
}

bool ValidUtf8(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    const int extra = c < 0x80             ? 0
                      : (c & 0xE0) == 0xC0 ? 1
                      : (c & 0xF0) == 0xE0 ? 2
                      : (c & 0xF8) == 0xF0 ? 3
                                           : -1;
    if (extra < 0 || s.size() - i <= static_cast<size_t>(extra)) return false;
    for (int k = 1; k <= extra; ++k) {
      if ((static_cast<unsigned char>(s[i + k]) & 0xC0) != 0x80) return false;
    }
    i += 1 + extra;
  }
  return true;
}

void AppendUtf8(uint32_t cp, std::string* out) {
  if (cp == 0 || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) cp = '?';
  if (cp < 0x80) {
    *out += static_cast<char>(cp);
  } else if (cp < 0x800) {
    *out += static_cast<char>(0xC0 | (cp >> 6));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  } else if (cp < 0x10000) {
    *out += static_cast<char>(0xE0 | (cp >> 12));
    *out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  } else {
    *out += static_cast<char>(0xF0 | (cp >> 18));
    *out += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
    *out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  }
}

// Text of a pre-2007 file is in the drawing's code page ($DWGCODEPAGE, ANSI_1252 by default);
// from R2007 on it is UTF-8. Bytes iconv cannot convert become '?'.
std::string ToUtf8(const std::string& s, const std::string& codepage) {
  if (ValidUtf8(s)) return s;
  iconv_t cd = iconv_open("UTF-8", codepage.c_str());
  if (cd == reinterpret_cast<iconv_t>(-1)) cd = iconv_open("UTF-8", "CP1252");
  std::string out;
  if (cd == reinterpret_cast<iconv_t>(-1)) {
    for (char c : s) out += static_cast<unsigned char>(c) < 0x80 ? c : '?';
    return out;
  }
  std::string in = s;
  char* ip = in.data();
  size_t il = in.size();
  std::string buf(4 * in.size() + 4, '\0');
  char* op = buf.data();
  size_t ol = buf.size();
  while (il > 0) {
    if (iconv(cd, &ip, &il, &op, &ol) == static_cast<size_t>(-1)) {
      if (ol == 0) break;
      *op++ = '?';
      --ol;
      ++ip;
      --il;
    }
  }
  iconv_close(cd);
  buf.resize(buf.size() - ol);
  return buf;
}

// "\U+XXXX" escapes (both TEXT and MTEXT) at s[i]; returns the characters consumed or 0.
size_t UnicodeEscape(const std::string& s, size_t i, std::string* out) {
  if (i + 7 <= s.size() && s.compare(i, 3, "\\U+") == 0) {
    const std::string hex = s.substr(i + 3, 4);
    if (std::all_of(hex.begin(), hex.end(),
                    [](char c) { return std::isxdigit(static_cast<unsigned char>(c)); })) {
      AppendUtf8(static_cast<uint32_t>(std::strtoul(hex.c_str(), nullptr, 16)), out);
      return 7;
    }
  }
  return 0;
}

// TEXT and ATTRIB control codes: %%c diameter, %%d degree, %%p plus-minus, %%nnn a character
// code, %%u/%%o/%%k underline/overline/strike toggles (the lines are not drawn: *approx).
std::string PlainText(const std::string& s, bool* approx) {
  std::string out;
  for (size_t i = 0; i < s.size();) {
    if (const size_t n = UnicodeEscape(s, i, &out)) {
      i += n;
    } else if (s.compare(i, 2, "%%") == 0 && i + 2 < s.size()) {
      const char k = static_cast<char>(std::tolower(static_cast<unsigned char>(s[i + 2])));
      if (k == 'c') {
        AppendUtf8(0x00D8, &out);
      } else if (k == 'd') {
        AppendUtf8(0x00B0, &out);
      } else if (k == 'p') {
        AppendUtf8(0x00B1, &out);
      } else if (k == '%') {
        out += '%';
      } else if (k == 'u' || k == 'o' || k == 'k') {
        *approx = true;
      } else if (std::isdigit(static_cast<unsigned char>(k))) {
        size_t e = i + 2;
        uint32_t cp = 0;
        while (e < s.size() && e < i + 5 && std::isdigit(static_cast<unsigned char>(s[e]))) {
          cp = cp * 10 + static_cast<uint32_t>(s[e] - '0');
          ++e;
        }
        AppendUtf8(cp, &out);
        i = e;
        continue;
      } else {
        out += s.substr(i, 3);
      }
      i += 3;
    } else {
      out += s[i++];
    }
  }
  return out;
}

// MTEXT with its inline codes stripped. A font (\f), height (\H) or width factor (\W) set
// before the first character applies to the whole text; set later (mixed formatting within
// one MTEXT) it cannot be honoured by one RenderText call and makes the result approximate.
struct Mtext {
  std::string text;
  std::string font;  // family from \f or file from \F, empty if none
  bool font_is_file = false;
  double height = 0.0;  // from \H, 0 if none
  bool height_relative = false;
  double width = 0.0;  // from \W, 0 if none
  bool approx = false;
};

Mtext PlainMtext(const std::string& s) {
  Mtext m;
  bool seen = false;           // a visible character was written
  auto arg = [&](size_t* i) {  // the argument up to ';' after a code letter at s[*i + 1]
    const size_t start = *i + 2;
    size_t e = s.find(';', start);
    if (e == std::string::npos) e = s.size();
    *i = std::min(e + 1, s.size());
    return s.substr(start, e - start);
  };
  for (size_t i = 0; i < s.size();) {
    const char c = s[i];
    if (c == '\\' && i + 1 < s.size()) {
      if (const size_t n = UnicodeEscape(s, i, &m.text)) {
        i += n;
        seen = true;
        continue;
      }
      const char k = s[i + 1];
      switch (k) {
        case 'P':
        case 'X':
        case 'N':
          m.text += '\n';
          i += 2;
          break;
        case '~':
          m.text += ' ';
          i += 2;
          break;
        case '\\':
        case '{':
        case '}':
          m.text += k;
          seen = true;
          i += 2;
          break;
        case 'M':  // \M+nXXXX: a double-byte character of a big font
          m.text += '?';
          m.approx = true;
          i = std::min(i + 8, s.size());
          break;
        case 'f':
        case 'F': {
          // \fArial|b1|i0|c0|p34; a TrueType family with bold and italic flags; \Fromans.shx;
          // or \Fromans|c0; a font file.
          const std::string a = arg(&i);
          std::string font = Trim(a.substr(0, a.find('|')));
          const bool file = k == 'F' || Lower(font).find(".shx") != std::string::npos;
          if (!file && a.find("|b1") != std::string::npos) font += ":bold";
          if (!file && a.find("|i1") != std::string::npos) font += ":italic";
          if (seen) {
            m.approx = true;
          } else if (!font.empty()) {
            m.font = font;
            m.font_is_file = file;
          }
          break;
        }
        case 'H':
        case 'W': {
          const std::string a = Trim(arg(&i));
          const bool rel = !a.empty() && (a.back() == 'x' || a.back() == 'X');
          const double v = std::atof(a.c_str());
          if (seen || !(v > 0)) {
            m.approx = true;
          } else if (k == 'H') {
            m.height = v;
            m.height_relative = rel;
          } else {
            m.width = v;
          }
          break;
        }
        case 'Q':
        case 'T': {
          const std::string a = arg(&i);
          if (std::atof(a.c_str()) != (k == 'T' ? 1.0 : 0.0)) m.approx = true;
          break;
        }
        case 'A':
        case 'C':
        case 'c':
        case 'p':
          arg(&i);  // alignment within the line, colour, paragraph indents: no geometry
          break;
        case 'S': {  // stacked fraction 1/2, 1^2, 1#2: drawn inline as "1/2"
          std::string a = arg(&i);
          std::replace(a.begin(), a.end(), '^', '/');
          std::replace(a.begin(), a.end(), '#', '/');
          m.text += a;
          m.approx = true;
          seen = true;
          break;
        }
        case 'L':
        case 'O':
        case 'K':
          m.approx = true;  // underline, overline, strike-through: the lines are not drawn
          i += 2;
          break;
        case 'l':
        case 'o':
        case 'k':
          i += 2;
          break;
        default:
          m.text += k;
          seen = true;
          i += 2;
      }
    } else if (c == '{' || c == '}') {
      ++i;
    } else if (c == '^' && i + 1 < s.size()) {
      const char k = s[i + 1];
      if (k == 'I') m.text += "    ";
      if (k == 'J') m.text += '\n';
      if (k == ' ') m.text += '^';
      i += 2;
    } else {
      m.text += c;
      if (!std::isspace(static_cast<unsigned char>(c))) seen = true;
      ++i;
    }
  }
  return m;
}

bool Blank(const std::string& s) {
  return std::all_of(s.begin(), s.end(),
                     [](char c) { return std::isspace(static_cast<unsigned char>(c)); });
}

// SHX fonts are not on a Linux system; AutoCAD's own are Hershey designs (simplex = Roman
// Simplex, complex = Roman Complex, ...), so they map to those, everything else to futural,
// the single-stroke engraving face.
std::string HersheyFor(const std::string& stem) {
  static const std::map<std::string, std::string> kMap = {
      {"romans", "rowmans"},    {"simplex", "rowmans"},   {"romand", "rowmand"},
      {"romant", "rowmant"},    {"romanc", "timesr"},     {"complex", "timesr"},
      {"italicc", "timesi"},    {"italic", "timesi"},     {"italict", "timesib"},
      {"scripts", "scripts"},   {"scriptc", "scriptc"},   {"gothice", "gothiceng"},
      {"gothicg", "gothicger"}, {"gothici", "gothicita"}, {"greeks", "greeks"},
      {"greekc", "greekc"},     {"cyrillic", "cyrillic"}, {"cyriltlc", "cyrilc_1"},
  };
  const auto it = kMap.find(stem);
  return "hershey:" + (it != kMap.end() ? it->second : std::string("futural"));
}

// Windows font file names -> the families fontconfig knows (or aliases to metric twins).
std::string FamilyForFile(const std::string& stem) {
  static const std::map<std::string, std::string> kMap = {
      {"arial", "Arial"},
      {"arialbd", "Arial:bold"},
      {"ariali", "Arial:italic"},
      {"arialbi", "Arial:bold:italic"},
      {"arialn", "Arial Narrow"},
      {"times", "Times New Roman"},
      {"timesbd", "Times New Roman:bold"},
      {"timesi", "Times New Roman:italic"},
      {"cour", "Courier New"},
      {"courbd", "Courier New:bold"},
      {"calibri", "Calibri"},
      {"cambria", "Cambria"},
      {"verdana", "Verdana"},
      {"tahoma", "Tahoma"},
      {"consola", "Consolas"},
      {"georgia", "Georgia"},
      {"trebuc", "Trebuchet MS"},
      {"comic", "Comic Sans MS"},
      {"impact", "Impact"},
      {"segoeui", "Segoe UI"},
      {"isocpeur", "ISOCPEUR"},
      {"isocteur", "ISOCTEUR"},
  };
  const auto it = kMap.find(stem);
  return it != kMap.end() ? it->second : stem;
}

struct StyleDef {
  std::string font_file;  // group 3: "arial.ttf", "txt", "romans.shx"
  std::string family;     // XDATA ACAD 1000: the TrueType family AutoCAD uses
  double fixed_height = 0.0;
  double width = 1.0;
  double oblique_deg = 0.0;
  int flags = 0;  // 2 backward, 4 upside down
};

struct Block {
  size_t begin = 0, end = 0;  // its entities
  Vector3d base = Vector3d::Zero();
  int flags = 0;
  std::string xref;
};

enum class Role { kCurve, kHatch, kText, kArea };

struct OutPath {
  Polyline path;
  Role role = Role::kCurve;
  bool dropped = false;
};

struct Box {
  Vector2d lo{1e300, 1e300}, hi{-1e300, -1e300};
  void Add(const Vector2d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  bool Empty() const { return lo.x() > hi.x(); }
};

double Area(const std::vector<Vector2d>& p) {
  double a = 0;
  for (size_t k = 0; k < p.size(); ++k) {
    const Vector2d& u = p[k];
    const Vector2d& v = p[(k + 1) % p.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return 0.5 * a;
}

double Perimeter(const std::vector<Vector2d>& p) {
  double l = 0;
  for (size_t k = 0; k < p.size(); ++k) l += (p[(k + 1) % p.size()] - p[k]).norm();
  return l;
}

double DistanceToLoop(const Vector2d& q, const std::vector<Vector2d>& p) {
  double best = 1e300;
  for (size_t k = 0; k < p.size(); ++k) {
    const Vector2d& u = p[k];
    const Vector2d d = p[(k + 1) % p.size()] - u;
    const double l2 = d.squaredNorm();
    const double t = l2 > 0 ? std::clamp((q - u).dot(d) / l2, 0.0, 1.0) : 0.0;
    best = std::min(best, (u + t * d - q).squaredNorm());
  }
  return std::sqrt(best);
}

// Two closed paths trace the same loop within d (either direction, any start): their boxes,
// their areas (offsetting a loop by d changes its area by at most d x perimeter) and up to 64
// vertices of each against the other agree.
bool SameLoop(const std::vector<Vector2d>& a, const std::vector<Vector2d>& b, double d) {
  Box ba, bb;
  for (const Vector2d& p : a) ba.Add(p);
  for (const Vector2d& p : b) bb.Add(p);
  if ((ba.lo - bb.lo).cwiseAbs().maxCoeff() > d || (ba.hi - bb.hi).cwiseAbs().maxCoeff() > d) {
    return false;
  }
  if (std::abs(std::abs(Area(a)) - std::abs(Area(b))) > d * (Perimeter(a) + Perimeter(b))) {
    return false;
  }
  for (int pass = 0; pass < 2; ++pass) {
    const auto& from = pass == 0 ? a : b;
    const auto& to = pass == 0 ? b : a;
    const size_t step = std::max<size_t>(1, from.size() / 64);
    for (size_t k = 0; k < from.size(); k += step) {
      if (DistanceToLoop(from[k], to) > d) return false;
    }
  }
  return true;
}

struct UnionFind {
  std::vector<size_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  size_t Find(size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void Join(size_t a, size_t b) { parent[Find(a)] = Find(b); }
};

class DxfReader {
 public:
  DxfReader(std::string origin, double tol) : origin_(std::move(origin)), tol_(tol) {}

  Status Read(const std::string& text) {
    INSITU_RETURN_IF_ERROR(Tokenize(text));
    size_t header_a = 0, header_b = 0, tables_a = 0, tables_b = 0, blocks_a = 0, blocks_b = 0;
    size_t ent_a = 0, ent_b = 0;
    bool have_entities = false;
    for (size_t i = 0; i + 1 < groups_.size(); ++i) {
      if (groups_[i].code != 0 || groups_[i].value != "SECTION" || groups_[i + 1].code != 2)
        continue;
      const std::string name = Upper(groups_[i + 1].value);
      size_t e = i + 2;
      while (e < groups_.size() && !(groups_[e].code == 0 && groups_[e].value == "ENDSEC")) ++e;
      if (name == "HEADER") header_a = i + 2, header_b = e;
      if (name == "TABLES") tables_a = i + 2, tables_b = e;
      if (name == "BLOCKS") blocks_a = i + 2, blocks_b = e;
      if (name == "ENTITIES" && !have_entities) ent_a = i + 2, ent_b = e, have_entities = true;
      i = e;
    }
    if (!have_entities) return ParseError(origin_ + ": no ENTITIES section");
    ReadHeader(header_a, header_b);
    ReadStyles(tables_a, tables_b);
    ReadBlocks(blocks_a, blocks_b);
    return Draw(ent_a, ent_b, Scale(unit_mm_, unit_mm_, unit_mm_), 0);
  }

  VectorPattern Finish() {
    Box box;
    for (const OutPath& o : outs_) {
      for (const Vector2d& p : o.path.points) box.Add(p);
    }
    const double extent = box.Empty() ? 0.0 : (box.hi - box.lo).maxCoeff();
    // Ends that meet: an arc's end is computed from its centre, radius and angles, a line's is
    // printed, and the two agree to the digits the writer printed: 6 decimal places in R12-era
    // and plotter writers (5e-7 units, 1.3e-5 mm in inches), about 7 significant digits in
    // writers that use floats (1e-6 of the drawing's size), far closer with doubles. 0.001 mm
    // covers the first, a fiftieth of a typical spot; 1e-6 of the extent the second. A wider
    // gap is in the drawing, and closing it would invent an area the designer left open.
    const double join_tol = std::max(0.001, 1e-6 * extent);
    JoinChains(join_tol);
    DropRepeatedHatchLoops(2 * tol_ + join_tol);
    for (OutPath& o : outs_) {
      if (!o.dropped) out_.paths.push_back(std::move(o.path));
    }
    for (const auto& [message, first] : text_failures_) {
      out_.warnings.push_back(std::to_string(first.second) +
                              " text item(s) not drawn (first at line " +
                              std::to_string(first.first) + "): " + message);
    }
    if (approx_texts_ > 0) {
      out_.warnings.push_back(std::to_string(approx_texts_) +
                              " text item(s) with formatting drawn approximately (inline font or "
                              "height changes, stacked fractions, underlines)");
    }
    if (wide_mtext_ > 0) {
      out_.warnings.push_back(std::to_string(wide_mtext_) +
                              " MTEXT item(s) wider than their column: lines are broken only "
                              "where the text has line breaks");
    }
    out_.units = units_;
    return std::move(out_);
  }

 private:
  Status Error(size_t k, const std::string& message) const {
    const int line = k < groups_.size() ? groups_[k].line : line_count_;
    return ParseError(origin_ + ": line " + std::to_string(line) + ": " + message);
  }

  // A warning once per `key` (by default its text): a drawing with a thousand inserts of a
  // missing block says so once. The job report names the file.
  void Warn(const std::string& w, const std::string& key = "") {
    if (warned_.insert(key.empty() ? w : key).second) out_.warnings.push_back(w);
  }

  // One pass over the lines: (code, value) pairs up to the first 0/EOF.
  Status Tokenize(const std::string& text) {
    static const char kBinary[] = "AutoCAD Binary DXF";
    if (text.compare(0, sizeof(kBinary) - 1, kBinary) == 0) {
      return ParseError(origin_ +
                        ": a binary DXF file: insitu reads ASCII DXF (save or export "
                        "the drawing as ASCII DXF)");
    }
    size_t pos = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
    // Classic Mac OS files end lines with '\r' alone.
    const char eol = text.find('\n') == std::string::npos ? '\r' : '\n';
    int line = 0;
    auto next = [&](std::string* out) {
      if (pos >= text.size()) return false;
      size_t e = text.find(eol, pos);
      if (e == std::string::npos) e = text.size();
      *out = text.substr(pos, e - pos);
      if (!out->empty() && out->back() == '\r') out->pop_back();
      pos = e + 1;
      ++line;
      return true;
    };
    bool in_entities = false, entities_done = false, eof = false;
    std::string code_line, value;
    while (next(&code_line)) {
      const std::string c = Trim(code_line);
      if (c.empty() && pos >= text.size()) break;  // a last empty line
      char* end = nullptr;
      const long code = std::strtol(c.c_str(), &end, 10);
      if (c.empty() || *end != '\0' || code < -5 || code > 1071) {
        if (entities_done) {
          Warn("line " + std::to_string(line) + ": '" + c.substr(0, 20) +
               "' is not a DXF group code; the rest of the file (after the ENTITIES section) "
               "is ignored");
          eof = true;
          break;
        }
        return ParseError(origin_ + ": line " + std::to_string(line) + ": '" + c.substr(0, 40) +
                          "' is not a DXF group code");
      }
      const int code_at = line;
      if (!next(&value)) {
        if (entities_done) break;
        return ParseError(origin_ + ": line " + std::to_string(line) +
                          ": a group code without its value");
      }
      Group g;
      g.code = static_cast<int>(code);
      g.line = code_at;
      g.value = (g.code == 1 || g.code == 3) ? value : Trim(value);
      if (NumericCode(g.code)) {
        const std::string t = Trim(value);
        char* stop = nullptr;
        g.num = std::strtod(t.c_str(), &stop);
        g.numeric = !t.empty() && *stop == '\0' && std::isfinite(g.num);
      }
      if (g.code == 0 && g.value == "EOF") {
        eof = true;
        break;
      }
      if (g.code == 2 && g.value == "ENTITIES" && !groups_.empty() && groups_.back().code == 0 &&
          groups_.back().value == "SECTION") {
        in_entities = true;
      }
      if (g.code == 0 && g.value == "ENDSEC" && in_entities) {
        in_entities = false;
        entities_done = true;
      }
      groups_.push_back(std::move(g));
    }
    line_count_ = line;
    if (groups_.empty()) return ParseError(origin_ + ": empty file");
    if (!eof && in_entities) {
      return ParseError(origin_ + ": line " + std::to_string(line) +
                        ": the file ends inside its ENTITIES section (cut short?)");
    }
    if (!eof && entities_done) Warn("no EOF marker after the ENTITIES section (read anyway)");
    return Status::Ok();
  }

  void ReadHeader(size_t a, size_t b) {
    bool unitless = true;
    int measurement = -1;
    for (size_t i = a; i + 1 < b; ++i) {
      if (groups_[i].code != 9) continue;
      const std::string& var = groups_[i].value;
      const Group& v = groups_[i + 1];
      if (var == "$INSUNITS" && v.numeric) {
        unit_mm_ = InsUnitsToMm(ToInt(v.num), &units_);
        unitless = !(v.num >= 1 && v.num <= 14);
      } else if (var == "$MEASUREMENT" && v.numeric) {
        measurement = ToInt(v.num);
      } else if (var == "$DWGCODEPAGE" && v.code == 3) {
        std::string cp = Upper(v.value);
        if (cp.rfind("ANSI_", 0) == 0) cp = "CP" + cp.substr(5);
        if (cp.size() > 2 && cp.size() < 16) codepage_ = cp;
      }
    }
    if (unitless && measurement == 0) {
      Warn(
          "the drawing names no units but is imperial ($MEASUREMENT 0): read as mm, scale the "
          "pattern if it was drawn in inches");
    }
  }

  void ReadStyles(size_t a, size_t b) {
    for (size_t i = a; i < b; ++i) {
      if (groups_[i].code != 0 || groups_[i].value != "STYLE") continue;
      size_t e = i + 1;
      while (e < b && groups_[e].code != 0) ++e;
      StyleDef s;
      std::string name;
      bool acad = false;
      for (size_t k = i + 1; k < e; ++k) {
        const Group& g = groups_[k];
        if (g.code == 2) name = Upper(g.value);
        if (g.code == 3) s.font_file = g.value;
        if (g.code == 40 && g.numeric) s.fixed_height = g.num;
        if (g.code == 41 && g.numeric && g.num > 0) s.width = g.num;
        if (g.code == 50 && g.numeric) s.oblique_deg = g.num;
        if (g.code == 71 && g.numeric) s.flags = ToInt(g.num);
        if (g.code == 1001) acad = g.value == "ACAD";
        if (g.code == 1000 && acad && s.family.empty()) s.family = Trim(g.value);
      }
      if (!name.empty()) styles_[name] = s;
      i = e - 1;
    }
  }

  void ReadBlocks(size_t a, size_t b) {
    for (size_t i = a; i < b; ++i) {
      if (groups_[i].code != 0 || groups_[i].value != "BLOCK") continue;
      size_t h = i + 1;
      while (h < b && groups_[h].code != 0) ++h;
      Block blk;
      std::string name;
      for (size_t k = i + 1; k < h; ++k) {
        const Group& g = groups_[k];
        if (g.code == 2 || (g.code == 3 && name.empty())) name = Upper(g.value);
        if (g.code == 70 && g.numeric) blk.flags = ToInt(g.num);
        if (g.code == 1) blk.xref = g.value;
      }
      blk.base = Point(i, h, 10);
      size_t e = h;
      while (e < b && !(groups_[e].code == 0 &&
                        (groups_[e].value == "ENDBLK" || groups_[e].value == "BLOCK"))) {
        ++e;
      }
      blk.begin = h;
      blk.end = e;
      if (!name.empty() && !blocks_.count(name)) blocks_[name] = blk;
      i = e > i ? e - 1 : i;
    }
  }

  // Group lookups within one entity [a, b).
  const Group* Find(size_t a, size_t b, int code) const {
    for (size_t k = a + 1; k < b; ++k) {
      if (groups_[k].code == code) return &groups_[k];
    }
    return nullptr;
  }
  bool Has(size_t a, size_t b, int code) const { return Find(a, b, code) != nullptr; }
  double Num(size_t a, size_t b, int code, double fallback) const {
    const Group* g = Find(a, b, code);
    return g && g->numeric ? g->num : fallback;
  }
  int Int(size_t a, size_t b, int code, int fallback) const {
    const Group* g = Find(a, b, code);
    return g && g->numeric ? ToInt(g->num) : fallback;
  }
  Vector3d Point(size_t a, size_t b, int code) const {
    return Vector3d(Num(a, b, code, 0), Num(a, b, code + 10, 0), Num(a, b, code + 20, 0));
  }
  Affine3d Ocs(size_t a, size_t b) const {
    return Linear(OcsToWcs(Vector3d(Num(a, b, 210, 0), Num(a, b, 220, 0), Num(a, b, 230, 1))));
  }
  // The end of an entity's own groups: R2018 puts an embedded MTEXT after "101 Embedded
  // Object", whose groups repeat the entity's codes.
  size_t Core(size_t a, size_t b) const {
    for (size_t k = a + 1; k < b; ++k) {
      if (groups_[k].code == 101) return k;
    }
    return b;
  }
  size_t NextEntity(size_t a, size_t end) const {
    size_t k = a + 1;
    while (k < end && groups_[k].code != 0) ++k;
    return k;
  }

  // The groups that must be there, and every number this reader takes is one.
  Status Need(size_t a, size_t b, std::initializer_list<int> codes, const std::string& type) const {
    for (int code : codes) {
      if (!Has(a, b, code)) {
        return Error(a, type + " without group " + std::to_string(code));
      }
    }
    for (size_t k = a + 1; k < b && groups_[k].code != 1001; ++k) {
      const Group& g = groups_[k];
      if (CheckedCode(g.code) && !g.numeric) {
        return ParseError(origin_ + ": line " + std::to_string(g.line + 1) + ": " + type +
                          " group " + std::to_string(g.code) + ": '" + g.value.substr(0, 40) +
                          "' is not a number");
      }
    }
    return Status::Ok();
  }

  void Count(const std::string& kind) { ++out_.converted[kind]; }
  void Skip(const std::string& kind) { ++out_.skipped[kind]; }

  // A path in the entity's coordinates, through `m` to mm on the XY plane.
  void Emit(const std::vector<Vector3d>& local, const Affine3d& m, bool closed, Role role) {
    std::vector<Vector2d> pts;
    pts.reserve(local.size());
    for (const Vector3d& p : local) {
      const Vector2d q = (m * p).head<2>();
      if (!q.allFinite()) {
        overflow_ = true;
        return;
      }
      if (!pts.empty() && (q - pts.back()).squaredNorm() == 0.0) continue;
      pts.push_back(q);
    }
    if (closed && pts.size() > 1 && (pts.back() - pts.front()).squaredNorm() == 0.0) pts.pop_back();
    if (pts.size() < 2) return;  // a point: nothing to mark
    points_ += static_cast<int64_t>(pts.size());
    OutPath o;
    o.path.points = std::move(pts);
    o.path.closed = closed && o.path.points.size() >= 3;
    o.role = role;
    outs_.push_back(std::move(o));
  }

  // Flattening tolerance in the entity's own units under transform m.
  double LocalTol(const Affine3d& m) const { return tol_ / std::max(Stretch(m), 1e-12); }

  Status Draw(size_t begin, size_t end, const Affine3d& m, int depth) {
    size_t i = begin;
    while (i < end) {
      if (groups_[i].code != 0) {
        ++i;
        continue;
      }
      const size_t a = i;
      const size_t b = NextEntity(a, end);
      const std::string type = Upper(groups_[a].value);
      // POLYLINE's VERTEXes and INSERT's ATTRIBs, up to their SEQEND, belong to them.
      size_t next = b;
      if (type == "POLYLINE" || type == "INSERT") {
        const char* sub = type == "POLYLINE" ? "VERTEX" : "ATTRIB";
        while (next < end && groups_[next].code == 0 && Upper(groups_[next].value) == sub) {
          next = NextEntity(next, end);
        }
        if (next < end && groups_[next].code == 0 && Upper(groups_[next].value) == "SEQEND") {
          next = NextEntity(next, end);
        }
      }
      if (++visits_ > kMaxEntityVisits) {
        return OutOfRange(origin_ + ": line " + std::to_string(groups_[a].line) +
                          ": the drawing expands to more than " + std::to_string(kMaxEntityVisits) +
                          " entities (nested block arrays?)");
      }
      if (Int(a, b, 67, 0) == 1) {
        Skip("paper_space");  // layouts and title blocks, not the model
      } else {
        INSITU_RETURN_IF_ERROR(Entity(type, a, b, next, m, depth));
      }
      if (overflow_) {
        return Error(a, type + ": coordinates beyond the range of numbers once scaled to mm");
      }
      if (points_ > kMaxPoints) {
        return OutOfRange(origin_ + ": line " + std::to_string(groups_[a].line) +
                          ": the drawing flattens to more than " + std::to_string(kMaxPoints) +
                          " points");
      }
      i = next;
    }
    return Status::Ok();
  }

  Status Entity(const std::string& type, size_t a, size_t b, size_t next, const Affine3d& m,
                int depth) {
    if (type == "LINE") return Line(a, b, m);
    if (type == "CIRCLE" || type == "ARC") return ArcCircle(type, a, b, m);
    if (type == "ELLIPSE") return Ellipse(a, b, m);
    if (type == "LWPOLYLINE") return LwPolyline(a, b, m);
    if (type == "POLYLINE") return OldPolyline(a, b, next, m);
    if (type == "SPLINE") return SplineEntity(a, b, m);
    if (type == "HATCH") return Hatch(a, b, m);
    if (type == "SOLID" || type == "TRACE") return Solid(type, a, b, m);
    if (type == "TEXT" || type == "ATTRIB" || type == "ATTDEF") return Text(type, a, b, m);
    if (type == "MTEXT") return MText(a, b, m);
    if (type == "INSERT") return Insert(a, b, next, m, depth);
    if (type == "DIMENSION") return Dimension(a, b, m, depth);
    Skip(Kind(type));  // 3DFACE, MESH, 3DSOLID, REGION, BODY, IMAGE, VIEWPORT, POINT, LEADER...
    return Status::Ok();
  }

  Status Line(size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20, 11, 21}, "LINE"));
    Emit({Point(a, b, 10), Point(a, b, 11)}, m, false, Role::kCurve);
    Count("line");
    return Status::Ok();
  }

  Status ArcCircle(const std::string& type, size_t a, size_t b, const Affine3d& m) {
    const bool arc = type == "ARC";
    INSITU_RETURN_IF_ERROR(Need(a, b,
                                arc ? std::initializer_list<int>{10, 20, 40, 50, 51}
                                    : std::initializer_list<int>{10, 20, 40},
                                type));
    const double r = Num(a, b, 40, 0);
    if (!(r > 0)) return Error(a, type + " radius must be > 0");
    const Affine3d me = m * Ocs(a, b);
    const Vector3d c = Point(a, b, 10);
    std::vector<Vector2d> pts;
    if (arc) {
      const double s = Num(a, b, 50, 0), e = Num(a, b, 51, 0);
      AppendArc(c.head<2>(), r, std::fmod(s, 360.0) * kDeg, SweepDeg(s, e) * kDeg, LocalTol(me),
                &pts, true);
    } else {
      AppendArc(c.head<2>(), r, 0.0, 2 * M_PI, LocalTol(me), &pts, true);
      pts.pop_back();
    }
    Emit(Lift(pts, c.z()), me, !arc, Role::kCurve);
    Count(Kind(type));
    return Status::Ok();
  }

  Status Ellipse(size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20, 11, 21, 40}, "ELLIPSE"));
    const Vector3d c = Point(a, b, 10), major = Point(a, b, 11);
    const double ratio = Num(a, b, 40, 1);
    Vector3d n(Num(a, b, 210, 0), Num(a, b, 220, 0), Num(a, b, 230, 1));
    if (!(n.norm() > 1e-12)) n = Vector3d::UnitZ();
    if (!(major.norm() > 0) || !(ratio > 0)) {
      return Error(a, "ELLIPSE needs a major axis and a ratio > 0");
    }
    const Vector3d minor = ratio * n.normalized().cross(major);
    const double t0 = Num(a, b, 41, 0), t1 = Num(a, b, 42, 2 * M_PI);
    const double sweep = SweepRad(t0, t1);
    const bool full = std::abs(sweep - 2 * M_PI) < 1e-9;
    const int n_chords = ArcChords(major.norm(), sweep, LocalTol(m), 4);
    std::vector<Vector3d> pts;
    const double start = std::fmod(t0, 2 * M_PI);
    for (int k = 0; k < (full ? n_chords : n_chords + 1); ++k) {
      const double t = start + sweep * k / n_chords;
      pts.push_back(c + std::cos(t) * major + std::sin(t) * minor);
    }
    Emit(pts, m, full, Role::kCurve);
    Count("ellipse");
    return Status::Ok();
  }

  void NoteWidth(bool wide) {
    if (wide) Warn("wide polylines are drawn along their centre line (their width is not filled)");
  }

  Status LwPolyline(size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20}, "LWPOLYLINE"));
    const Affine3d me = m * Ocs(a, b);
    std::vector<Vector2d> v;
    std::vector<double> bulge;
    bool wide = Num(a, b, 43, 0) > 0;
    BulgedVertices(a + 1, b, &v, &bulge, &wide);
    const bool closed = (Int(a, b, 70, 0) & 1) != 0;
    Emit(Lift(Bulged(v, bulge, closed, LocalTol(me)), Num(a, b, 38, 0)), me, closed, Role::kCurve);
    NoteWidth(wide);
    Count("lwpolyline");
    return Status::Ok();
  }

  // The vertices (10/20) and bulges (42) of groups [from, to), as LWPOLYLINE and a HATCH's
  // polyline loop list them; `wide`, if given, set by a nonzero width (40/41).
  void BulgedVertices(size_t from, size_t to, std::vector<Vector2d>* v,
                      std::vector<double>* bulge, bool* wide) const {
    for (size_t k = from; k < to; ++k) {
      const Group& g = groups_[k];
      if (g.code == 10) {
        v->emplace_back(g.num, 0.0);
        bulge->push_back(0.0);
      } else if (g.code == 20 && !v->empty()) {
        v->back().y() = g.num;
      } else if (g.code == 42 && !v->empty()) {
        bulge->back() = g.num;
      } else if (wide != nullptr && (g.code == 40 || g.code == 41) && g.num > 0) {
        *wide = true;
      }
    }
  }

  // POLYLINE followed by VERTEX entities up to SEQEND (b .. next).
  Status OldPolyline(size_t a, size_t b, size_t next, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {}, "POLYLINE"));
    const int flags = Int(a, b, 70, 0);
    if (flags & 64) {
      Skip("polyface_mesh");
      return Status::Ok();
    }
    if (flags & 16) {
      Skip("polygon_mesh");
      return Status::Ok();
    }
    const bool is3d = (flags & 8) != 0;
    const Affine3d me = is3d ? m : m * Ocs(a, b);
    const double z = Num(a, b, 30, 0);
    std::vector<Vector3d> v3;
    std::vector<Vector2d> v;
    std::vector<double> bulge;
    bool wide = Num(a, b, 40, 0) > 0 || Num(a, b, 41, 0) > 0;
    for (size_t i = b; i < next;) {
      const size_t e = NextEntity(i, next);
      if (Upper(groups_[i].value) == "VERTEX") {
        INSITU_RETURN_IF_ERROR(Need(i, e, {10, 20}, "VERTEX"));
        const int vflags = Int(i, e, 70, 0);
        // A spline-fit polyline lists its frame (flag 16) and the fitted curve (flag 8).
        if (!((flags & 4) && (vflags & 16))) {
          const Vector3d p = Point(i, e, 10);
          v3.push_back(p);
          v.push_back(p.head<2>());
          bulge.push_back(Num(i, e, 42, 0));
          wide = wide || Num(i, e, 40, 0) > 0 || Num(i, e, 41, 0) > 0;
        }
      }
      i = e;
    }
    const bool closed = (flags & 1) != 0;
    if (is3d) {
      Emit(v3, me, closed, Role::kCurve);
    } else {
      Emit(Lift(Bulged(v, bulge, closed, LocalTol(me)), z), me, closed, Role::kCurve);
      NoteWidth(wide);
    }
    Count("polyline");
    return Status::Ok();
  }

  // A (rational) B-spline by de Boor in homogeneous coordinates at evenly spaced parameters.
  // A chord c on a curve of radius R departs from it by c^2 / (8 R): chords of sqrt(8 R tol)
  // stay within the tolerance; R >= 1 mm is assumed (tighter bends in a marking pattern are
  // below the spot size anyway). The control polygon's length bounds the curve's.
  Result<std::vector<Vector3d>> EvalSpline(size_t at, int p, const std::vector<double>& u,
                                           const std::vector<Vector3d>& ctrl,
                                           const std::vector<double>& w, double stretch) const {
    const size_t n_ctrl = ctrl.size();
    if (p < 1 || p > kMaxSplineDegree || n_ctrl < static_cast<size_t>(p) + 1 ||
        u.size() != n_ctrl + p + 1) {
      return Error(at,
                   "SPLINE needs degree + 1 control points and #control + degree + 1 knots "
                   "(degree " +
                       std::to_string(p) + ", " + std::to_string(n_ctrl) + " control points, " +
                       std::to_string(u.size()) + " knots)");
    }
    for (size_t k = 1; k < u.size(); ++k) {
      if (u[k] < u[k - 1]) return Error(at, "SPLINE knots must not decrease");
    }
    const double u0 = u[p], u1 = u[u.size() - p - 1];
    if (!(u1 > u0)) return Error(at, "SPLINE knot span is empty");
    for (double wk : w) {
      if (!(wk > 0)) return Error(at, "SPLINE weights must be > 0");
    }
    constexpr double kMinRadiusMm = 1.0;
    double length = 0;
    for (size_t k = 1; k < n_ctrl; ++k) length += (ctrl[k] - ctrl[k - 1]).norm();
    const double want = length * stretch / std::sqrt(8.0 * kMinRadiusMm * tol_);
    const int n = static_cast<int>(std::clamp(std::isfinite(want) ? want : 0.0, 16.0, 20000.0));
    std::vector<Vector3d> out;
    out.reserve(n + 1);
    std::vector<Eigen::Vector4d> d(p + 1);
    for (int s = 0; s <= n; ++s) {
      const double t = std::min(u0 + (u1 - u0) * s / n, u1 - 1e-12 * (u1 - u0));
      size_t k = p;
      while (k + 1 < u.size() - p - 1 && u[k + 1] <= t) ++k;
      for (int j = 0; j <= p; ++j) {
        const size_t c = k - p + j;
        const double wc = w.empty() ? 1.0 : w[c];
        d[j] << wc * ctrl[c], wc;
      }
      for (int r = 1; r <= p; ++r) {
        for (int j = p; j >= r; --j) {
          const size_t i = k - p + j;
          const double denom = u[i + p - r + 1] - u[i];
          const double alpha = denom > 0 ? (t - u[i]) / denom : 0.0;
          d[j] = (1 - alpha) * d[j - 1] + alpha * d[j];
        }
      }
      out.push_back(d[p].head<3>() / d[p].w());
    }
    return out;
  }

  Status SplineEntity(size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {}, "SPLINE"));
    const int flags = Int(a, b, 70, 0);
    const int degree = Int(a, b, 71, 3);
    std::vector<double> knots, weights;
    std::vector<Vector3d> ctrl, fit;
    for (size_t k = a + 1; k < b; ++k) {
      const Group& g = groups_[k];
      if (g.code == 40) knots.push_back(g.num);
      if (g.code == 41) weights.push_back(g.num);
      if (g.code == 10) ctrl.emplace_back(g.num, 0, 0);
      if (g.code == 20 && !ctrl.empty()) ctrl.back().y() = g.num;
      if (g.code == 30 && !ctrl.empty()) ctrl.back().z() = g.num;
      if (g.code == 11) fit.emplace_back(g.num, 0, 0);
      if (g.code == 21 && !fit.empty()) fit.back().y() = g.num;
      if (g.code == 31 && !fit.empty()) fit.back().z() = g.num;
    }
    if (ctrl.empty() && fit.size() >= 2) {
      Skip("spline_fit_points");
      Warn("line " + std::to_string(groups_[a].line) +
               ": a SPLINE given by fit points only is not drawn (re-save it with control "
               "points); skipped[\"spline_fit_points\"] counts them all",
           "spline_fit_points");
      return Status::Ok();
    }
    if (weights.size() != ctrl.size()) weights.clear();
    INSITU_ASSIGN_OR_RETURN(std::vector<Vector3d> pts,
                            EvalSpline(a, degree, knots, ctrl, weights, Stretch(m)));
    Emit(pts, m, (flags & 1) != 0, Role::kCurve);
    Count("spline");
    return Status::Ok();
  }

  Status Solid(const std::string& type, size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20, 11, 21, 12, 22}, type));
    // Vertex order 1, 2, 4, 3 (the quadrilateral is stored as a triangle strip); a triangle
    // repeats its third point as the fourth.
    const Vector3d p3 = Point(a, b, 12);
    const Vector3d p4 = Has(a, b, 13) ? Point(a, b, 13) : p3;
    Emit({Point(a, b, 10), Point(a, b, 11), p4, p3}, m * Ocs(a, b), true, Role::kArea);
    Count(Kind(type));
    return Status::Ok();
  }

  // HATCH: boundary loops after group 91, each introduced by its 92 flags, up to the pattern
  // data (75 style onwards). Polyline loops: 72 has-bulge, 73 closed, 93 count, 10/20 [42].
  // Edge loops: 93 count, then per edge 72 type (1 line, 2 arc, 3 elliptic arc, 4 spline),
  // closed by 97 + 330 source handles.
  Status Hatch(size_t a, size_t b, const Affine3d& m) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {91}, "HATCH"));
    const Affine3d me = m * Ocs(a, b);
    const double tol = LocalTol(me);
    size_t k91 = a + 1;
    while (groups_[k91].code != 91) ++k91;
    const double z = Num(a, k91, 30, 0);
    size_t lend = k91 + 1;
    while (lend < b && groups_[lend].code != 75 && groups_[lend].code != 76 &&
           groups_[lend].code != 98 && groups_[lend].code != 450) {
      ++lend;
    }
    std::vector<size_t> starts;
    for (size_t k = k91 + 1; k < lend; ++k) {
      if (groups_[k].code == 92) starts.push_back(k);
    }
    starts.push_back(lend);
    // Hatch style 75: 0 fills by parity through every loop (the even-odd rule), 1 only between
    // the external (flag 1) and outermost (16) loops, 2 inside the external loops alone.
    const int style = Int(a, b, 75, 0);
    int kept_flags = ~0;
    for (size_t s = 0; s + 1 < starts.size() && style != 0; ++s) {
      if (ToInt(groups_[starts[s]].num) & 1) kept_flags = style == 1 ? (1 | 16) : 1;
    }
    int loops = 0;
    for (size_t s = 0; s + 1 < starts.size(); ++s) {
      const size_t la = starts[s], lb = starts[s + 1];
      if (!(ToInt(groups_[la].num) & kept_flags)) continue;
      std::vector<Vector2d> loop;
      if (ToInt(groups_[la].num) & 2) {
        std::vector<Vector2d> v;
        std::vector<double> bulge;
        BulgedVertices(la + 1, lb, &v, &bulge, nullptr);
        loop = Bulged(v, bulge, true, tol);
      } else {
        // The source handles end the loop; a spline edge's fit data may hold a 97 of its own.
        size_t eb = lb;
        while (eb > la + 1 && groups_[eb - 1].code == 330) --eb;
        if (eb > la + 1 && groups_[eb - 1].code == 97) --eb;
        std::vector<size_t> edges;
        for (size_t k = la + 1; k < eb; ++k) {
          if (groups_[k].code == 72) edges.push_back(k);
        }
        edges.push_back(eb);
        for (size_t e = 0; e + 1 < edges.size(); ++e) {
          INSITU_ASSIGN_OR_RETURN(std::vector<Vector2d> pts,
                                  HatchEdge(edges[e], edges[e + 1], tol, Stretch(me)));
          if (pts.empty()) continue;
          // Edges should run head to tail; some writers reverse one.
          if (!loop.empty() &&
              (pts.back() - loop.back()).norm() < (pts.front() - loop.back()).norm()) {
            std::reverse(pts.begin(), pts.end());
          }
          for (const Vector2d& p : pts) {
            if (loop.empty() || (p - loop.back()).norm() > 1e-12) loop.push_back(p);
          }
        }
        if (loop.size() > 1 && (loop.back() - loop.front()).norm() < 1e-9) loop.pop_back();
      }
      if (loop.size() >= 3) {
        Emit(Lift(loop, z), me, true, Role::kHatch);
        ++loops;
      }
    }
    if (loops > 0) {
      Count("hatch");
    } else {
      Skip("empty_hatch");
    }
    return Status::Ok();
  }

  Result<std::vector<Vector2d>> HatchEdge(size_t ea, size_t eb, double tol, double stretch) {
    const int type = ToInt(groups_[ea].num);
    const Vector2d c(Num(ea, eb, 10, 0), Num(ea, eb, 20, 0));
    std::vector<Vector2d> pts;
    if (type == 1) {
      INSITU_RETURN_IF_ERROR(Need(ea, eb, {10, 20, 11, 21}, "HATCH line edge"));
      return std::vector<Vector2d>{c, Vector2d(Num(ea, eb, 11, 0), Num(ea, eb, 21, 0))};
    }
    if (type == 2 || type == 3) {
      INSITU_RETURN_IF_ERROR(Need(ea, eb, {10, 20, 40, 50, 51}, "HATCH arc edge"));
      const bool ccw = Int(ea, eb, 73, 1) != 0;
      double s = Num(ea, eb, 50, 0), e = Num(ea, eb, 51, 360);
      // Clockwise edges store 360 - angle: the same arc counterclockwise runs from 360 - e to
      // 360 - s, and is reversed below.
      if (!ccw) {
        const double cw_start = s;
        s = 360.0 - e;
        e = 360.0 - cw_start;
      }
      const double sweep = SweepDeg(s, e) * kDeg;
      if (type == 2) {
        const double r = Num(ea, eb, 40, 0);
        if (!(r > 0)) return Error(ea, "HATCH arc edge radius must be > 0");
        AppendArc(c, r, std::fmod(s, 360.0) * kDeg, sweep, tol, &pts, true);
      } else {
        INSITU_RETURN_IF_ERROR(Need(ea, eb, {11, 21}, "HATCH elliptic edge"));
        const Vector2d major(Num(ea, eb, 11, 0), Num(ea, eb, 21, 0));
        const double ratio = Num(ea, eb, 40, 1);
        if (!(major.norm() > 0) || !(ratio > 0)) {
          return Error(ea, "HATCH elliptic edge needs a major axis and a ratio > 0");
        }
        const Vector2d minor = ratio * Vector2d(-major.y(), major.x());
        // The angles are geometric; the parameter of angle a is atan2(sin a / ratio, cos a).
        const double rs = std::fmod(s, 360.0) * kDeg;
        const double t0 = std::atan2(std::sin(rs) / ratio, std::cos(rs));
        const double re = rs + sweep;
        double t1 = std::atan2(std::sin(re) / ratio, std::cos(re));
        const double tsweep = std::abs(sweep - 2 * M_PI) < 1e-9 ? 2 * M_PI : SweepRad(t0, t1);
        const int n = ArcChords(major.norm(), tsweep, tol, 4);
        for (int k = 0; k <= n; ++k) {
          const double t = t0 + tsweep * k / n;
          pts.push_back(c + std::cos(t) * major + std::sin(t) * minor);
        }
      }
      if (!ccw) std::reverse(pts.begin(), pts.end());
      return pts;
    }
    if (type == 4) {
      const int degree = Int(ea, eb, 94, 3);
      std::vector<double> knots, weights;
      std::vector<Vector3d> ctrl;
      std::vector<Vector2d> fit;
      for (size_t k = ea + 1; k < eb; ++k) {
        const Group& g = groups_[k];
        if (g.code == 40) knots.push_back(g.num);
        if (g.code == 42) weights.push_back(g.num);
        if (g.code == 10) ctrl.emplace_back(g.num, 0, 0);
        if (g.code == 20 && !ctrl.empty()) ctrl.back().y() = g.num;
        if (g.code == 11) fit.emplace_back(g.num, 0);
        if (g.code == 21 && !fit.empty()) fit.back().y() = g.num;
      }
      if (ctrl.empty() && fit.size() >= 2) {
        Warn("line " + std::to_string(groups_[ea].line) +
                 ": a HATCH spline edge given by fit points only is drawn through them as "
                 "straight lines (and any others like it)",
             "hatch_fit_points");
        return fit;
      }
      if (weights.size() != ctrl.size()) weights.clear();
      INSITU_ASSIGN_OR_RETURN(std::vector<Vector3d> p3,
                              EvalSpline(ea, degree, knots, ctrl, weights, stretch));
      for (const Vector3d& p : p3) pts.push_back(p.head<2>());
      return pts;
    }
    return Error(ea, "HATCH edge type " + groups_[ea].value + " (expected 1 to 4)");
  }

  // Text.
  // The font of a style, or of an MTEXT's inline \f family / \F font file.
  std::string FontFor(const std::string& style_name, const Mtext* inline_font = nullptr) {
    if (inline_font && !inline_font->font.empty()) {
      return inline_font->font_is_file ? FontForFile(inline_font->font) : inline_font->font;
    }
    const StyleDef& s = Style(style_name);
    if (!s.family.empty()) return s.family;
    return FontForFile(s.font_file);
  }

  // A font file name: TrueType/OpenType/Type 1 -> its family for fontconfig; anything else
  // (txt, romans.shx, a LibreCAD .lff) -> a Hershey font.
  std::string FontForFile(const std::string& name) {
    std::string file = name;
    const size_t slash = file.find_last_of("/\\");
    if (slash != std::string::npos) file = file.substr(slash + 1);
    const size_t dot = file.rfind('.');
    const std::string stem = Lower(Trim(file.substr(0, dot)));
    const std::string ext = dot == std::string::npos ? "" : Lower(file.substr(dot + 1));
    if (ext == "ttf" || ext == "otf" || ext == "ttc" || ext == "pfb" || ext == "pfa") {
      return FamilyForFile(stem);
    }
    const std::string hershey = HersheyFor(stem.empty() ? "txt" : stem);
    Warn("font '" + (name.empty() ? std::string("txt") : name) +
         "' (an AutoCAD shape font) drawn as " + hershey);
    return hershey;
  }

  const StyleDef& Style(const std::string& name) {
    static const StyleDef kDefault;
    const auto it = styles_.find(Upper(name.empty() ? "STANDARD" : name));
    return it != styles_.end() ? it->second : kDefault;
  }

  // RenderText at unit cap height, shared by identical texts (an attribute in each of a
  // thousand inserted blocks). The tolerance is rounded down to a power of two for the key.
  const Result<VectorPattern>& Render(const std::string& text, const std::string& font,
                                      TextAlign align, double tol_unit) {
    tol_unit = std::isfinite(tol_unit) ? std::clamp(tol_unit, 1e-6, 0.05) : 0.05;
    tol_unit = std::exp2(std::floor(std::log2(tol_unit)));
    const std::string key = font + '\x1f' + std::to_string(static_cast<int>(align)) + '\x1f' +
                            std::to_string(tol_unit) + '\x1f' + text;
    auto it = text_cache_.find(key);
    if (it == text_cache_.end()) {
      if (text_cache_.size() >= kMaxTextCache) text_cache_.clear();
      TextStyle style;
      style.font = font;
      style.height_mm = 1.0;
      style.align = align;
      it = text_cache_.emplace(key, RenderText(text, style, tol_unit)).first;
    }
    return it->second;
  }

  void TextFailed(const std::string& kind, size_t a, const Status& s) {
    Skip(kind);
    auto& [first, count] = text_failures_[s.message()];
    if (count++ == 0) first = groups_[a].line;
  }

  // Rendered glyphs (unit cap height) through `place` into the pattern.
  void EmitText(const VectorPattern& glyphs, const Affine3d& place) {
    for (const Polyline& p : glyphs.paths) {
      std::vector<Vector3d> local;
      local.reserve(p.points.size());
      for (const Vector2d& q : p.points) local.emplace_back(q.x(), q.y(), 0.0);
      Emit(local, place, p.closed, Role::kText);
    }
    ++out_.texts;
    AddGlyphCounts(glyphs);
  }

  // The renderer's counts (glyphs drawn, characters the font lacks) and warnings.
  void AddGlyphCounts(const VectorPattern& glyphs) {
    for (const auto& [kind, n] : glyphs.converted) out_.converted[kind] += n;
    for (const auto& [kind, n] : glyphs.skipped) out_.skipped[kind] += n;
    for (const std::string& w : glyphs.warnings) Warn(w);
  }

  static Box Bounds(const VectorPattern& p) {
    Box box;
    for (const Polyline& l : p.paths) {
      for (const Vector2d& q : l.points) box.Add(q);
    }
    return box;
  }

  Status Text(const std::string& type, size_t a, size_t b, const Affine3d& m) {
    const std::string kind = Kind(type);
    b = Core(a, b);
    const int aflags = Int(a, b, 70, 0);
    if (type == "ATTDEF" && (!(aflags & 2) || (aflags & 1))) {
      ++out_.ignored_commands;  // a template for the ATTRIBs of each insert, not drawn itself
      return Status::Ok();
    }
    if (type == "ATTRIB" && (aflags & 1)) {
      Skip("invisible_attrib");
      return Status::Ok();
    }
    INSITU_RETURN_IF_ERROR(Need(a, b, {}, type));
    const Group* raw = Find(a, b, 1);
    bool approx = false;
    const std::string text = raw ? PlainText(ToUtf8(raw->value, codepage_), &approx) : "";
    if (Blank(text)) {
      ++out_.ignored_commands;  // an empty text draws nothing in CAD either
      return Status::Ok();
    }
    const Group* style_group = Find(a, b, 7);
    const std::string style_name = style_group ? style_group->value : "";
    const StyleDef& style = Style(style_name);
    double h = Num(a, b, 40, 0);
    if (!(h > 0)) h = style.fixed_height;
    if (!(h > 0)) {
      TextFailed(kind, a, ParseError(type + " without a height (group 40)"));
      return Status::Ok();
    }
    const double rot = Num(a, b, 50, 0) * kDeg;
    double wf = Has(a, b, 41) ? Num(a, b, 41, 1) : style.width;
    if (!(wf > 0)) wf = 1.0;
    const double oblique =
        std::clamp(Has(a, b, 51) ? Num(a, b, 51, 0) : style.oblique_deg, -85.0, 85.0);
    const int gen = Has(a, b, 71) ? Int(a, b, 71, 0) : style.flags;
    const int halign = Int(a, b, 72, 0);
    const int valign = Int(a, b, type == "TEXT" ? 73 : 74, 0);
    const Vector3d p1 = Point(a, b, 10);
    const Vector3d p2 = Has(a, b, 11) ? Point(a, b, 11) : p1;
    const TextAlign align = (halign == 1 || halign == 4) ? TextAlign::kCenter
                            : halign == 2                ? TextAlign::kRight
                                                         : TextAlign::kLeft;
    const Affine3d me = m * Ocs(a, b);
    // Glyph frame: mirror flags, oblique (shear of x by y), width factor, cap height.
    Eigen::Matrix3d shape = Eigen::Matrix3d::Identity();
    shape(0, 1) = std::tan(oblique * kDeg);
    const Affine3d mirror = Scale((gen & 2) ? -1.0 : 1.0, (gen & 4) ? -1.0 : 1.0, 1.0);
    Affine3d place = me * Translate(p1) * RotZ(rot) * mirror * Linear(shape) * Scale(wf * h, h, h);
    const Result<VectorPattern>& r =
        Render(text, FontFor(style_name), align, tol_ / std::max(Stretch(place), 1e-12));
    if (!r.ok()) {
      TextFailed(kind, a, r.status());
      return Status::Ok();
    }
    const Box box = Bounds(*r);
    const Vector2d d = (p2 - p1).head<2>();
    if ((halign == 3 || halign == 5) && d.norm() > 0 && !box.Empty() && box.hi.x() > 0) {
      // Aligned (3) scales the text to run from the first to the second point, fit (5) only
      // stretches it; both along the line between them.
      const double sx = d.norm() / box.hi.x();
      const double sy = halign == 3 ? sx : h;
      place = me * Translate(p1) * RotZ(std::atan2(d.y(), d.x())) * mirror * Linear(shape) *
              Scale(sx, sy, sy);
    } else {
      // Any other alignment positions the text at the second point; the vertical alignment
      // moves the baseline (bottom: a descender of 0.3 cap heights, the usual font's).
      double shift = 0.0;
      if (valign == 1) shift = 0.3;
      if (valign == 2 || (halign == 4 && valign == 0)) shift = -0.5;
      if (valign == 3) shift = -1.0;
      const Vector3d at = (halign != 0 || valign != 0) ? p2 : p1;
      place = me * Translate(at) * RotZ(rot) * mirror * Linear(shape) * Scale(wf * h, h, h) *
              Translate(Vector3d(0, shift, 0));
    }
    EmitText(*r, place);
    if (approx) ++approx_texts_;
    Count(kind);
    return Status::Ok();
  }

  // MTEXT: insertion point (10) and x direction (11, or rotation 50 in degrees) in WCS, the
  // attachment point (71: 1..9 = top/middle/bottom x left/centre/right), nominal cap height
  // (40), line spacing factor (44; AutoCAD's single spacing is 5/3 of the cap height). Each
  // line is rendered on its own so the spacing is AutoCAD's whatever the font's metrics.
  Status MText(size_t a, size_t b, const Affine3d& m) {
    b = Core(a, b);
    INSITU_RETURN_IF_ERROR(Need(a, b, {}, "MTEXT"));
    std::string raw;
    for (size_t k = a + 1; k < b; ++k) {
      if (groups_[k].code == 3 || groups_[k].code == 1) raw += groups_[k].value;
    }
    const Mtext mt = PlainMtext(ToUtf8(raw, codepage_));
    if (Blank(mt.text)) {
      ++out_.ignored_commands;
      return Status::Ok();
    }
    const Group* style_group = Find(a, b, 7);
    const std::string style_name = style_group ? style_group->value : "";
    const StyleDef& style = Style(style_name);
    double h = Num(a, b, 40, 0);
    if (!(h > 0)) h = style.fixed_height;
    if (mt.height > 0) h = mt.height_relative ? h * mt.height : mt.height;
    if (!(h > 0)) {
      TextFailed("mtext", a, ParseError("MTEXT without a height (group 40)"));
      return Status::Ok();
    }
    const double wf = mt.width > 0 ? mt.width : style.width;
    Vector3d n(Num(a, b, 210, 0), Num(a, b, 220, 0), Num(a, b, 230, 1));
    if (!(n.norm() > 1e-12)) n = Vector3d::UnitZ();
    n.normalize();
    Vector3d x = Has(a, b, 11)
                     ? Point(a, b, 11)
                     : Vector3d(OcsToWcs(n) * Vector3d(std::cos(Num(a, b, 50, 0) * kDeg),
                                                       std::sin(Num(a, b, 50, 0) * kDeg), 0));
    x -= x.dot(n) * n;
    if (!(x.norm() > 1e-12)) x = OcsToWcs(n).col(0);
    x.normalize();
    Eigen::Matrix3d frame;
    frame.col(0) = x;
    frame.col(1) = n.cross(x);
    frame.col(2) = n;
    const int attach = std::clamp(Int(a, b, 71, 1), 1, 9);
    const TextAlign align = (attach - 1) % 3 == 0   ? TextAlign::kLeft
                            : (attach - 1) % 3 == 1 ? TextAlign::kCenter
                                                    : TextAlign::kRight;
    std::vector<std::string> lines;
    size_t start = 0;
    while (true) {
      const size_t e = mt.text.find('\n', start);
      lines.push_back(
          mt.text.substr(start, e == std::string::npos ? std::string::npos : e - start));
      if (e == std::string::npos) break;
      start = e + 1;
    }
    const double spacing = 5.0 / 3.0 * std::clamp(Num(a, b, 44, 1.0), 0.25, 4.0);  // cap heights
    const double block = 1.0 + spacing * static_cast<double>(lines.size() - 1);
    double first = 0.0;  // baseline of the first line, in cap heights below the point
    if (attach <= 3) first = -1.0;
    if (attach >= 4 && attach <= 6) first = block / 2.0 - 1.0;
    if (attach >= 7) first = block - 1.0;
    const Affine3d base = m * Translate(Point(a, b, 10)) * Linear(frame) * Scale(wf * h, h, h);
    const std::string font = FontFor(style_name, &mt);
    const double tol_unit = tol_ / std::max(Stretch(base), 1e-12);
    const double column = Num(a, b, 41, 0);
    bool drawn = false, wide = false;
    for (size_t l = 0; l < lines.size(); ++l) {
      if (Blank(lines[l])) continue;
      const Result<VectorPattern>& r = Render(lines[l], font, align, tol_unit);
      if (!r.ok()) {
        TextFailed("mtext", a, r.status());
        return Status::Ok();
      }
      const Box box = Bounds(*r);
      if (column > 0 && !box.Empty() && (box.hi.x() - box.lo.x()) * wf * h > 1.05 * column) {
        wide = true;
      }
      const Affine3d place =
          base * Translate(Vector3d(0, first - spacing * static_cast<double>(l), 0));
      for (const Polyline& p : r->paths) {
        std::vector<Vector3d> local;
        for (const Vector2d& q : p.points) local.emplace_back(q.x(), q.y(), 0.0);
        Emit(local, place, p.closed, Role::kText);
      }
      AddGlyphCounts(*r);
      drawn = true;
    }
    if (drawn) {
      ++out_.texts;
      Count("mtext");
      if (mt.approx) ++approx_texts_;
      if (wide) ++wide_mtext_;
    }
    return Status::Ok();
  }

  const Block* FindBlock(const std::string& name) const {
    const auto it = blocks_.find(Upper(name));
    return it != blocks_.end() ? &it->second : nullptr;
  }

  // Draws a block's entities through m, guarding against a block that contains itself.
  Status DrawBlock(size_t a, const std::string& name, const Block& blk, const Affine3d& m,
                   int depth) {
    const std::string key = Upper(name);
    if (std::find(stack_.begin(), stack_.end(), key) != stack_.end()) {
      std::string chain;
      for (const std::string& s : stack_) chain += s + " -> ";
      return Error(a, "block '" + name + "' inserts itself (" + chain + key + ")");
    }
    if (depth + 1 > kMaxBlockDepth) {
      return OutOfRange(
          Error(a, "blocks nested deeper than " + std::to_string(kMaxBlockDepth) + " levels")
              .message());
    }
    stack_.push_back(key);
    const Status s = Draw(blk.begin, blk.end, m, depth + 1);
    stack_.pop_back();
    return s;
  }

  Status Insert(size_t a, size_t b, size_t next, const Affine3d& m, int depth) {
    INSITU_RETURN_IF_ERROR(Need(a, b, {2}, "INSERT"));
    const std::string name = Find(a, b, 2)->value;
    const Block* blk = FindBlock(name);
    if (!blk) {
      Skip("missing_block");
      Warn("line " + std::to_string(groups_[a].line) + ": INSERT of block '" + name +
               "', which the file does not define",
           "missing block " + Upper(name));
    } else if (blk->flags & 4) {
      Skip("xref");
      Warn("line " + std::to_string(groups_[a].line) + ": block '" + name +
               "' is an external reference (" + blk->xref + "): bind it in CAD to mark it",
           "xref " + Upper(name));
    } else {
      const int cols = std::max(1, Int(a, b, 70, 1)), rows = std::max(1, Int(a, b, 71, 1));
      if (static_cast<int64_t>(cols) * rows > kMaxArrayCopies) {
        return OutOfRange(Error(a, "INSERT array of " + std::to_string(rows) + " x " +
                                       std::to_string(cols) + " copies (at most " +
                                       std::to_string(kMaxArrayCopies) + ")")
                              .message());
      }
      // Each copy counts as a visit whatever it holds: arrays of empty blocks nested in
      // arrays would otherwise multiply calls without limit.
      visits_ += static_cast<int64_t>(cols) * rows;
      if (visits_ > kMaxEntityVisits) {
        return OutOfRange(Error(a, "the drawing expands to more than " +
                                       std::to_string(kMaxEntityVisits) +
                                       " entities and block copies (nested block arrays?)")
                              .message());
      }
      const double dx = Num(a, b, 44, 0), dy = Num(a, b, 45, 0);
      const Affine3d placed =
          m * Ocs(a, b) * Translate(Point(a, b, 10)) * RotZ(Num(a, b, 50, 0) * kDeg);
      const Affine3d local =
          Scale(Num(a, b, 41, 1), Num(a, b, 42, 1), Num(a, b, 43, 1)) * Translate(-blk->base);
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          const Affine3d cell = placed * Translate(Vector3d(c * dx, r * dy, 0)) * local;
          INSITU_RETURN_IF_ERROR(DrawBlock(a, name, *blk, cell, depth));
        }
      }
      Count("insert");
    }
    // ATTRIBs are placed in the INSERT's own space, not the block's.
    for (size_t i = b; i < next;) {
      const size_t e = NextEntity(i, next);
      if (Upper(groups_[i].value) == "ATTRIB") INSITU_RETURN_IF_ERROR(Text("ATTRIB", i, e, m));
      i = e;
    }
    return Status::Ok();
  }

  // A DIMENSION is drawn by AutoCAD from its anonymous block (*D...), in WCS.
  Status Dimension(size_t a, size_t b, const Affine3d& m, int depth) {
    const Group* name = Find(a, b, 2);
    const Block* blk = name ? FindBlock(name->value) : nullptr;
    if (!blk || (blk->flags & 4)) {
      Skip("dimension");
      return Status::Ok();
    }
    INSITU_RETURN_IF_ERROR(DrawBlock(a, name->value, *blk, m, depth));
    Count("dimension");
    return Status::Ok();
  }

  // Open curves whose ends meet within `tol` become closed loops. Endpoints within tol are one
  // node. Curves with a free end (a tail, a leader touching an outline) are peeled off first,
  // repeatedly, and stay open; of what remains, a connected set of curves where every node
  // joins exactly two ends is a cycle, walked into one closed path. Where three or more ends
  // still meet (a figure eight, two outlines touching at a corner) the way round is ambiguous,
  // and those curves stay open.
  void JoinChains(double tol) {
    std::vector<size_t> open;
    for (size_t i = 0; i < outs_.size(); ++i) {
      if (outs_[i].role == Role::kCurve && !outs_[i].path.closed) open.push_back(i);
    }
    if (open.empty()) return;
    const size_t n_ends = 2 * open.size();
    auto end_point = [&](size_t e) -> const Vector2d& {
      const auto& pts = outs_[open[e / 2]].path.points;
      return e % 2 == 0 ? pts.front() : pts.back();
    };
    // Ends meet within `tol`: a grid of tol-sized cells, each end compared with the ends of
    // its cell and the 8 around it (linear in the ends however they line up; a sort on x
    // alone compared a dashed vertical line's ends all against all).
    UnionFind uf(n_ends);
    std::unordered_map<std::pair<int64_t, int64_t>, std::vector<size_t>, CellHash> grid;
    for (size_t e = 0; e < n_ends; ++e) grid[CellOf(end_point(e), tol)].push_back(e);
    for (size_t e = 0; e < n_ends; ++e) {
      const Vector2d& p = end_point(e);
      const auto [cx, cy] = CellOf(p, tol);
      for (int64_t gx = cx - 1; gx <= cx + 1; ++gx) {
        for (int64_t gy = cy - 1; gy <= cy + 1; ++gy) {
          const auto it = grid.find({gx, gy});
          if (it == grid.end()) continue;
          for (size_t f : it->second) {
            if (f > e && (end_point(f) - p).norm() <= tol) uf.Join(e, f);
          }
        }
      }
    }
    std::vector<size_t> node(n_ends);
    std::map<size_t, std::vector<size_t>> node_ends;  // node -> endpoints in it
    std::map<size_t, int> degree;                     // node -> ends of curves still in play
    for (size_t e = 0; e < n_ends; ++e) {
      node[e] = uf.Find(e);
      node_ends[node[e]].push_back(e);
      ++degree[node[e]];
    }
    std::vector<char> peeled(open.size(), 0);
    std::vector<size_t> leaves;
    for (const auto& [n, d] : degree) {
      if (d == 1) leaves.push_back(n);
    }
    while (!leaves.empty()) {
      const size_t n = leaves.back();
      leaves.pop_back();
      if (degree[n] != 1) continue;
      for (size_t e : node_ends[n]) {
        if (peeled[e / 2]) continue;
        peeled[e / 2] = 1;
        for (size_t f : {e - e % 2, e - e % 2 + 1}) {
          if (--degree[node[f]] == 1) leaves.push_back(node[f]);
        }
        break;
      }
    }
    // Components of the remaining curves through shared nodes.
    UnionFind comp(open.size());
    for (const auto& [n, ends] : node_ends) {
      for (size_t e : ends) comp.Join(ends[0] / 2, e / 2);
    }
    std::map<size_t, std::vector<size_t>> members;  // root -> curves, in file order
    for (size_t j = 0; j < open.size(); ++j) {
      if (!peeled[j]) members[comp.Find(j)].push_back(j);
    }
    for (const auto& [root, curves] : members) {
      bool cycle = true;
      for (size_t j : curves)
        cycle = cycle && degree[node[2 * j]] == 2 && degree[node[2 * j + 1]] == 2;
      if (!cycle) continue;
      // Walk: from the first curve's end, through the node's other end, until back.
      std::vector<Vector2d> loop = outs_[open[curves[0]]].path.points;
      std::vector<size_t> used = {curves[0]};
      size_t at = 2 * curves[0] + 1;
      for (size_t step = 0; step < curves.size(); ++step) {
        size_t other = at;
        for (size_t e : node_ends[node[at]]) {
          if (e != at && !peeled[e / 2]) other = e;
        }
        const size_t j = other / 2;
        if (other == at || j == curves[0]) break;
        std::vector<Vector2d> pts = outs_[open[j]].path.points;
        if (other % 2 == 1) std::reverse(pts.begin(), pts.end());
        loop.insert(loop.end(), pts.begin() + 1, pts.end());
        used.push_back(j);
        at = (other % 2 == 0) ? other + 1 : other - 1;
      }
      if (loop.size() > 1 && (loop.back() - loop.front()).norm() <= tol) loop.pop_back();
      if (loop.size() < 3) continue;
      for (size_t k = 1; k < used.size(); ++k) outs_[open[used[k]]].dropped = true;
      OutPath& first = outs_[open[curves[0]]];
      first.path.points = std::move(loop);
      first.path.closed = true;
      Count("chained_loop");
    }
  }

  // A hatch loop over an outline the drawing already has closed adds nothing but would cancel
  // it under the even-odd rule.
  void DropRepeatedHatchLoops(double d) {
    std::vector<Box> boxes(outs_.size());
    for (size_t i = 0; i < outs_.size(); ++i) {
      for (const Vector2d& p : outs_[i].path.points) boxes[i].Add(p);
    }
    auto near = [&](const Box& x, const Box& y) {
      return (x.lo - y.lo).cwiseAbs().maxCoeff() <= d && (x.hi - y.hi).cwiseAbs().maxCoeff() <= d;
    };
    // Candidates by their boxes' lower corners on a grid of d-sized cells: a hatch is compared
    // with the paths whose corner lies within a cell of its own (linear, where comparing
    // every hatch with every path took seconds on an arrayed hatch block).
    const double cell = std::max(d, 1e-9);
    std::unordered_map<std::pair<int64_t, int64_t>, std::vector<size_t>, CellHash> by_corner;
    for (size_t i = 0; i < outs_.size(); ++i) by_corner[CellOf(boxes[i].lo, cell)].push_back(i);
    for (size_t h = 0; h < outs_.size(); ++h) {
      if (outs_[h].role != Role::kHatch || outs_[h].dropped) continue;
      std::vector<size_t> candidates;
      const auto [cx, cy] = CellOf(boxes[h].lo, cell);
      for (int64_t gx = cx - 1; gx <= cx + 1; ++gx) {
        for (int64_t gy = cy - 1; gy <= cy + 1; ++gy) {
          const auto it = by_corner.find({gx, gy});
          if (it != by_corner.end()) candidates.insert(candidates.end(), it->second.begin(), it->second.end());
        }
      }
      std::sort(candidates.begin(), candidates.end());  // the first of two stays, as before
      for (size_t o : candidates) {
        if (o == h || outs_[o].dropped || !outs_[o].path.closed || outs_[o].role == Role::kText) {
          continue;
        }
        if (outs_[o].role == Role::kHatch && o > h) continue;  // keep the first of two
        if (near(boxes[h], boxes[o]) && SameLoop(outs_[h].path.points, outs_[o].path.points, d)) {
          outs_[h].dropped = true;
          ++out_.converted["hatch_loop_on_outline"];
          break;
        }
      }
    }
  }

  std::string origin_;
  double tol_;
  double unit_mm_ = 1.0;
  std::string units_ = "unitless (read as mm)";
  std::string codepage_ = "CP1252";
  int line_count_ = 0;
  std::vector<Group> groups_;
  std::map<std::string, StyleDef> styles_;
  std::map<std::string, Block> blocks_;
  std::vector<std::string> stack_;  // blocks being drawn, outermost first
  std::vector<OutPath> outs_;
  int64_t visits_ = 0, points_ = 0;
  bool overflow_ = false;  // a point came out infinite or NaN
  std::map<std::string, Result<VectorPattern>> text_cache_;
  std::map<std::string, std::pair<int, int>> text_failures_;  // message -> (first line, count)
  std::set<std::string> warned_;                              // keys of the warnings given
  int approx_texts_ = 0, wide_mtext_ = 0;
  VectorPattern out_;
};

}  // namespace

Result<VectorPattern> ParseDxf(const std::string& text, const std::string& origin,
                               double tolerance_mm) {
  if (!(tolerance_mm > 0)) return InvalidArgument("DXF flattening tolerance must be > 0");
  DxfReader reader(origin, tolerance_mm);
  INSITU_RETURN_IF_ERROR(reader.Read(text));
  VectorPattern out = reader.Finish();
  if (out.paths.empty()) {
    std::string what;
    for (const auto& [kind, n] : out.skipped)
      what += (what.empty() ? "" : ", ") + kind + " " + std::to_string(n);
    return InvalidArgument(origin + ": the DXF draws nothing insitu can mark" +
                           (what.empty() ? std::string() : " (not drawn: " + what + ")"));
  }
  return out;
}

Result<VectorPattern> LoadDxf(const std::string& path, double tolerance_mm) {
  INSITU_ASSIGN_OR_RETURN(const std::string text, ReadPatternFile(path, "DXF"));
  return ParseDxf(text, path, tolerance_mm);
}

}  // namespace insitu::pattern
