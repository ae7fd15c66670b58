// SVG input. tinyxml2 reads the XML; the rest is here (no SVG library in Debian fits: librsvg
// renders to pixels, which would lose the vector): the CSS cascade, <use> expansion, the path
// grammar, transforms, text through RenderText, and curve flattening.
//
// The reader walks the document as a renderer would, but of each element it keeps only the
// geometry to mark and one bit of its paint: a closed shape that is filled becomes an area to
// hatch, one with fill none an outline to follow (a laser marks lines; a colour means nothing
// to it). What a renderer would paint and a marking cannot hold (images, gradients, clipping,
// markers) is counted in VectorPattern::skipped by kind, so the job report says what of the
// design is not on the part.
//
// Files come from outside. Every number is read by a reader that owns its text and accepts
// only the SVG number grammar (no locale, no hex, no inf or nan); element nesting is bounded by
// tinyxml2 (100 levels) and kMaxUseDepth, and the work by kMaxElements and kMaxPoints, so a
// file whose <use> elements multiply (each instancing the previous ten times) fails with a
// message instead of exhausting memory.
#include <tinyxml2.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <unordered_map>
#include <utility>
#include <vector>

#include "insitu/pattern/text.h"
#include "insitu/pattern/vector.h"
#include "pattern/flatten.h"

namespace insitu::pattern {
namespace {

using Affine = Eigen::Affine2d;
using Vec = Eigen::Vector2d;
using tinyxml2::XMLElement;

constexpr int kMaxUseDepth = 16;        // <use> inside referenced content; clones of clones
constexpr int kMaxDepth = 256;          // elements inside elements, <use> included
constexpr long kMaxElements = 1000000;  // element instances drawn, <use> expanded
constexpr size_t kMaxPoints = 5000000;  // flattened points (80 MB)
constexpr size_t kMaxFileBytes = size_t{256} << 20;
constexpr size_t kMaxWarnings = 100;
constexpr size_t kMaxCssRules = 100000;
// Selector parts tried on elements: a 10^5-element drawing with a design tool's style sheet
// needs some 10^6.
constexpr double kMaxCssWork = 2e7;
constexpr double kPxPerMm = 96.0 / 25.4;  // CSS: 96 px per inch
constexpr double kMaxFontMm = 10000.0;    // an em larger than this is a broken transform

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f'; }
bool IsDigit(char c) { return c >= '0' && c <= '9'; }
bool IsAlpha(char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); }

std::string Trim(std::string_view s) {
  size_t a = 0, b = s.size();
  while (a < b && IsSpace(s[a])) ++a;
  while (b > a && IsSpace(s[b - 1])) --b;
  return std::string(s.substr(a, b - a));
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool StartsWith(std::string_view s, std::string_view prefix) {
  return s.substr(0, prefix.size()) == prefix;
}

// The end of an SVG number starting at s[i] (sign, digits with at most one '.', an exponent only
// when digits follow it), or i when none starts there.
size_t ScanNumber(std::string_view s, size_t i) {
  size_t j = i;
  if (j < s.size() && (s[j] == '+' || s[j] == '-')) ++j;
  int digits = 0;
  while (j < s.size() && IsDigit(s[j])) ++j, ++digits;
  if (j < s.size() && s[j] == '.') {
    ++j;
    while (j < s.size() && IsDigit(s[j])) ++j, ++digits;
  }
  if (digits == 0) return i;
  if (j < s.size() && (s[j] == 'e' || s[j] == 'E')) {
    size_t k = j + 1;
    if (k < s.size() && (s[k] == '+' || s[k] == '-')) ++k;
    if (k < s.size() && IsDigit(s[k])) {
      while (k < s.size() && IsDigit(s[k])) ++k;
      j = k;
    }
  }
  return j;
}

// A scanned number's value; false when it does not fit a finite double.
bool ToDouble(std::string_view s, double* out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  double v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

// Reads numbers out of SVG attribute text: separators are whitespace and commas, and a sign
// or a second '.' starts a new number ("1-2.5.5" is 1, -2.5, .5); arc flags may be packed.
// The reader owns a copy of its text, so it may be built from a temporary (an attribute value)
// and outlive it.
class NumberReader {
 public:
  explicit NumberReader(std::string s) : s_(std::move(s)) {}
  void SkipSeparators() {
    while (i_ < s_.size() && (IsSpace(s_[i_]) || s_[i_] == ',')) ++i_;
  }
  bool Number(double* out) {
    SkipSeparators();
    const size_t end = ScanNumber(s_, i_);
    if (end == i_) return false;
    if (!ToDouble(std::string_view(s_).substr(i_, end - i_), out)) return false;
    i_ = end;
    return true;
  }
  bool Flag(double* out) {  // "0" or "1", possibly without a separator after it
    SkipSeparators();
    if (i_ < s_.size() && (s_[i_] == '0' || s_[i_] == '1')) {
      *out = s_[i_++] - '0';
      return true;
    }
    return false;
  }
  bool Done() {
    SkipSeparators();
    return i_ >= s_.size();
  }
  char Peek() {
    SkipSeparators();
    return i_ < s_.size() ? s_[i_] : '\0';
  }
  void Advance() { ++i_; }
  size_t position() const { return i_; }

 private:
  std::string s_;
  size_t i_ = 0;
};

Result<Affine> ParseTransform(const std::string& text, const std::string& where) {
  Affine t = Affine::Identity();
  size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (IsSpace(text[i]) || text[i] == ',')) ++i;
    if (i >= text.size()) break;
    const size_t open = text.find('(', i), close = text.find(')', i);
    if (open == std::string::npos || close == std::string::npos || close < open) {
      return ParseError(where + ": transform '" + text + "' is malformed");
    }
    const std::string name = Trim(std::string_view(text).substr(i, open - i));
    const std::string args = text.substr(open + 1, close - open - 1);
    NumberReader r(args);
    std::vector<double> v;
    double x;
    while (v.size() < 7 && r.Number(&x)) v.push_back(x);
    if (!r.Done())
      return ParseError(where + ": transform " + name + "(" + args + ") has a non-number");
    Affine m = Affine::Identity();
    if (name == "matrix" && v.size() == 6) {
      m.matrix() << v[0], v[2], v[4], v[1], v[3], v[5], 0, 0, 1;
    } else if (name == "translate" && (v.size() == 1 || v.size() == 2)) {
      m.translate(Vec(v[0], v.size() == 2 ? v[1] : 0.0));
    } else if (name == "scale" && (v.size() == 1 || v.size() == 2)) {
      m.scale(Vec(v[0], v.size() == 2 ? v[1] : v[0]));
    } else if (name == "rotate" && (v.size() == 1 || v.size() == 3)) {
      const Vec c = v.size() == 3 ? Vec(v[1], v[2]) : Vec::Zero();
      m.translate(c).rotate(v[0] * M_PI / 180.0).translate(-c);
    } else if (name == "skewX" && v.size() == 1) {
      m.matrix()(0, 1) = std::tan(v[0] * M_PI / 180.0);
    } else if (name == "skewY" && v.size() == 1) {
      m.matrix()(1, 0) = std::tan(v[0] * M_PI / 180.0);
    } else {
      return ParseError(where + ": transform " + name + " with " + std::to_string(v.size()) +
                        " arguments is not an SVG transform");
    }
    t = t * m;
    i = close + 1;
  }
  return t;
}

// A length as written: "12.5", "3mm", "50%", "1.2em".
struct Length {
  double value = 0;
  std::string unit;  // lower case; empty for user units
};

std::optional<Length> ParseLength(std::string_view text) {
  const std::string s = Trim(text);
  const size_t end = ScanNumber(s, 0);
  if (end == 0) return std::nullopt;
  Length l;
  if (!ToDouble(std::string_view(s).substr(0, end), &l.value)) return std::nullopt;
  l.unit = Lower(s.substr(end));
  for (char c : l.unit) {
    if (!IsAlpha(c) && c != '%') return std::nullopt;
  }
  return l;
}

// User units (CSS px) per unit of `unit`, 0 for units that need a context (em, ex, %) or are
// unknown.
double PxPer(const std::string& unit) {
  if (unit.empty() || unit == "px") return 1.0;
  if (unit == "mm") return kPxPerMm;
  if (unit == "cm") return 10.0 * kPxPerMm;
  if (unit == "in") return 96.0;
  if (unit == "pt") return 96.0 / 72.0;
  if (unit == "pc") return 16.0;
  return 0.0;
}

// The root's width or height in mm, the name of its unit and that unit in mm ("100mm",
// "4in", "300", "300px"); false for a missing, relative or non-positive length.
bool LengthMm(const char* text, double* mm, std::string* unit_name, double* unit_mm) {
  if (text == nullptr) return false;
  const std::optional<Length> l = ParseLength(text);
  if (!l || !(l->value > 0)) return false;
  const double px = PxPer(l->unit);
  if (px == 0) return false;
  *unit_mm = px / kPxPerMm;
  *mm = l->value * *unit_mm;
  *unit_name = l->unit.empty() || l->unit == "px" ? "px (1/96 in)" : l->unit;
  return std::isfinite(*mm);
}

// viewBox="min-x min-y width height"; false unless four numbers with width, height > 0.
bool ParseViewBox(const char* text, double vb[4]) {
  NumberReader r(text);
  for (int k = 0; k < 4; ++k) {
    if (!r.Number(&vb[k])) return false;
  }
  return r.Done() && vb[2] > 0 && vb[3] > 0;
}

// The viewBox onto a viewport of w x h at the origin, by preserveAspectRatio (default
// xMidYMid meet: uniform scale, the whole viewBox visible, centred).
Affine ViewBoxTransform(const double vb[4], double w, double h, const char* par) {
  double ax = 0.5, ay = 0.5;
  bool none = false, slice = false;
  if (par != nullptr) {
    std::vector<std::string> words;
    std::string word;
    for (const char* c = par; *c; ++c) {
      if (IsSpace(*c)) {
        if (!word.empty()) words.push_back(word);
        word.clear();
      } else {
        word += *c;
      }
    }
    if (!word.empty()) words.push_back(word);
    size_t k = !words.empty() && words[0] == "defer" ? 1 : 0;
    if (k < words.size()) {
      const std::string& a = words[k];
      if (a == "none") {
        none = true;
      } else if (a.size() == 8 && a[0] == 'x' && a[4] == 'Y') {
        const auto f = [](std::string_view s) { return s == "Min" ? 0.0 : s == "Mid" ? 0.5 : 1.0; };
        ax = f(std::string_view(a).substr(1, 3));
        ay = f(std::string_view(a).substr(5, 3));
      }
      if (k + 1 < words.size()) slice = words[k + 1] == "slice";
    }
  }
  double sx = w / vb[2], sy = h / vb[3];
  if (!none) sx = sy = slice ? std::max(sx, sy) : std::min(sx, sy);
  Affine m = Affine::Identity();
  m.translate(Vec(ax * (w - vb[2] * sx), ay * (h - vb[3] * sy)));
  m.scale(Vec(sx, sy));
  m.translate(Vec(-vb[0], -vb[1]));
  return m;
}

// Namespaced elements of other vocabularies (sodipodi:namedview, i:pgf, ...) are editor data:
// an empty name. An "svg:" prefix is SVG.
std::string LocalName(const XMLElement* e) {
  std::string_view n = e->Name();
  if (StartsWith(n, "svg:")) n.remove_prefix(4);
  if (n.find(':') != std::string_view::npos) return "";
  return std::string(n);
}

const XMLElement* ParentElement(const XMLElement* e) {
  return e->Parent() != nullptr ? e->Parent()->ToElement() : nullptr;
}

std::vector<std::string> SplitSpaces(std::string_view s) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && IsSpace(s[i])) ++i;
    size_t j = i;
    while (j < s.size() && !IsSpace(s[j])) ++j;
    if (j > i) out.emplace_back(s.substr(i, j - i));
    i = j;
  }
  return out;
}

// CSS, the part that design tools write into <style>: rules of type, class and id selectors,
// compounds of them ("rect.a"), comma lists and descendant and child combinators; cascade by
// specificity (id > class > type) and then source order.

struct Declaration {
  std::string property;  // lower case
  std::string value;
  bool important = false;
};

// "fill:none; stroke : #000 !important". Quotes and parentheses may hold ';' (url(data:...)).
std::vector<Declaration> ParseDeclarations(std::string_view text) {
  std::vector<Declaration> out;
  size_t i = 0;
  while (i < text.size()) {
    size_t j = i;
    char quote = 0;
    int paren = 0;
    for (; j < text.size(); ++j) {
      const char c = text[j];
      if (quote != 0) {
        if (c == quote) quote = 0;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '(') {
        ++paren;
      } else if (c == ')' && paren > 0) {
        --paren;
      } else if (c == ';' && paren == 0) {
        break;
      }
    }
    const std::string_view decl = text.substr(i, j - i);
    i = j + 1;
    const size_t colon = decl.find(':');
    if (colon == std::string_view::npos) continue;
    Declaration d;
    d.property = Lower(Trim(decl.substr(0, colon)));
    d.value = Trim(decl.substr(colon + 1));
    const size_t bang = d.value.rfind('!');
    if (bang != std::string::npos && Lower(Trim(d.value.substr(bang + 1))) == "important") {
      d.important = true;
      d.value = Trim(d.value.substr(0, bang));
    }
    if (!d.property.empty()) out.push_back(std::move(d));
  }
  return out;
}

struct Compound {
  std::string type;  // empty or "*": any element
  std::string id;
  std::vector<std::string> classes;
};

struct Selector {
  std::vector<Compound> parts;    // left to right
  std::vector<char> combinators;  // between parts[k] and parts[k + 1]: ' ' or '>'
  int specificity = 0;            // ids * 10000 + classes * 100 + types
};

bool IdentChar(char c) {
  return IsAlpha(c) || IsDigit(c) || c == '-' || c == '_' || static_cast<unsigned char>(c) >= 0x80;
}

// Pseudo-classes, attribute selectors and the sibling combinators have no meaning for a file
// read once or are not written by design tools: nullopt.
std::optional<Selector> ParseSelector(std::string_view s) {
  Selector sel;
  Compound cur;
  bool have = false;
  char pending = 0;
  size_t i = 0;
  const auto ident = [&](std::string* out) {
    size_t j = i;
    while (j < s.size() && IdentChar(s[j])) ++j;
    if (j == i) return false;
    out->assign(s.substr(i, j - i));
    i = j;
    return true;
  };
  while (i < s.size()) {
    const char c = s[i];
    if (IsSpace(c)) {
      if (have && pending == 0) pending = ' ';
      ++i;
      continue;
    }
    if (c == '>') {
      if (!have) return std::nullopt;
      pending = '>';
      ++i;
      continue;
    }
    if (pending != 0) {
      sel.parts.push_back(std::move(cur));
      sel.combinators.push_back(pending);
      cur = Compound{};
      have = false;
      pending = 0;
      if (sel.parts.size() > 32) return std::nullopt;
    }
    if (c == '*') {
      if (have) return std::nullopt;
      cur.type = "*";
      ++i;
    } else if (c == '.') {
      ++i;
      std::string name;
      if (!ident(&name) || cur.classes.size() > 32) return std::nullopt;
      cur.classes.push_back(std::move(name));
    } else if (c == '#') {
      ++i;
      if (!cur.id.empty() || !ident(&cur.id)) return std::nullopt;
    } else if (IdentChar(c) && !have) {
      ident(&cur.type);
    } else {
      return std::nullopt;
    }
    have = true;
  }
  if (!have || pending == '>') return std::nullopt;
  sel.parts.push_back(std::move(cur));
  int ids = 0, classes = 0, types = 0;
  for (const Compound& p : sel.parts) {
    ids += p.id.empty() ? 0 : 1;
    classes += static_cast<int>(p.classes.size());
    types += p.type.empty() || p.type == "*" ? 0 : 1;
  }
  sel.specificity = std::min(ids, 99) * 10000 + std::min(classes, 99) * 100 + std::min(types, 99);
  return sel;
}

bool CompoundMatches(const Compound& c, const XMLElement* e) {
  if (!c.type.empty() && c.type != "*" && c.type != LocalName(e)) return false;
  if (!c.id.empty()) {
    const char* id = e->Attribute("id");
    if (id == nullptr || c.id != id) return false;
  }
  if (!c.classes.empty()) {
    const char* cls = e->Attribute("class");
    if (cls == nullptr) return false;
    const std::vector<std::string> have = SplitSpaces(cls);
    for (const std::string& want : c.classes) {
      if (std::find(have.begin(), have.end(), want) == have.end()) return false;
    }
  }
  return true;
}

// chain[0] is the element, chain[k + 1] the parent of chain[k]. Left to right over the parts:
// can[j] says parts[0..i] match with parts[i] on chain[j]; O(parts x depth), exact for both
// combinators.
bool SelectorMatches(const Selector& s, const std::vector<const XMLElement*>& chain) {
  const size_t d = chain.size();
  std::vector<char> can(d, 0), next(d, 0), any_above(d + 1, 0);
  for (size_t i = 0; i < s.parts.size(); ++i) {
    any_above[d] = 0;
    for (size_t j = d; j-- > 0;) any_above[j] = any_above[j + 1] || can[j];
    for (size_t j = 0; j < d; ++j) {
      bool ok = CompoundMatches(s.parts[i], chain[j]);
      if (ok && i > 0) {
        ok = s.combinators[i - 1] == '>' ? (j + 1 < d && can[j + 1]) : any_above[j + 1] != 0;
      }
      next[j] = ok;
    }
    std::swap(can, next);
  }
  return d > 0 && can[0];
}

class StyleSheet {
 public:
  // `css` is the text of the document's <style> elements, in order.
  void Parse(const std::string& raw, std::vector<std::string>* warnings) {
    const std::string css = StripComments(raw);
    size_t i = 0;
    while (i < css.size()) {
      while (i < css.size() && IsSpace(css[i])) ++i;
      if (i >= css.size()) break;
      if (css[i] == '@') {
        size_t j = i;
        while (j < css.size() && css[j] != ';' && css[j] != '{' && !IsSpace(css[j])) ++j;
        const std::string at = css.substr(i, j - i);
        while (j < css.size() && css[j] != ';' && css[j] != '{') ++j;
        j = j < css.size() && css[j] == '{' ? SkipBlock(css, j) : j + 1;
        if (at != "@charset" && at != "@font-face" && at != "@namespace") {
          warnings->push_back("CSS " + at + " rules are not applied");
        }
        i = j;
        continue;
      }
      const size_t open = css.find('{', i);
      if (open == std::string::npos) break;
      const size_t close = SkipBlock(css, open);
      const size_t body_end =
          close > open + 1 && close <= css.size() && css[close - 1] == '}' ? close - 1 : css.size();
      auto decls = std::make_shared<const std::vector<Declaration>>(
          ParseDeclarations(std::string_view(css).substr(open + 1, body_end - open - 1)));
      const std::string selectors = css.substr(i, open - i);
      size_t a = 0;
      while (a <= selectors.size()) {
        size_t b = selectors.find(',', a);
        if (b == std::string::npos) b = selectors.size();
        const std::string text = Trim(std::string_view(selectors).substr(a, b - a));
        if (rules_.size() >= kMaxCssRules) {
          warnings->push_back("CSS beyond " + std::to_string(kMaxCssRules) +
                              " rules is not applied");
          return;
        }
        if (std::optional<Selector> sel = ParseSelector(text)) {
          Add(std::move(*sel), decls);
        } else {
          warnings->push_back("CSS selector '" + text.substr(0, 80) +
                              "' is not supported: its declarations are not applied");
        }
        a = b + 1;
      }
      i = close;
    }
  }

  // The declarations whose selectors match `e`, in cascade order (later ones win). False once
  // the matching has cost more than kMaxCssWork, which only a hostile file asks for.
  bool Match(const XMLElement* e, std::vector<const Declaration*>* normal,
             std::vector<const Declaration*>* important) {
    if (rules_.empty()) return true;
    std::vector<int> candidates = universal_;
    const auto add = [&](const std::unordered_map<std::string, std::vector<int>>& index,
                         const std::string& key) {
      const auto it = index.find(key);
      if (it != index.end())
        candidates.insert(candidates.end(), it->second.begin(), it->second.end());
    };
    if (const char* id = e->Attribute("id")) add(by_id_, id);
    if (const char* cls = e->Attribute("class")) {
      for (const std::string& c : SplitSpaces(cls)) add(by_class_, c);
    }
    add(by_type_, LocalName(e));
    if (candidates.empty()) return true;
    std::sort(candidates.begin(), candidates.end());
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    std::vector<const XMLElement*> chain;
    for (const XMLElement* a = e; a != nullptr; a = ParentElement(a)) chain.push_back(a);
    std::vector<const Rule*> matched;
    for (int k : candidates) {
      work_ += static_cast<double>(rules_[k].selector.parts.size() * chain.size());
      if (work_ > kMaxCssWork) return false;
      if (SelectorMatches(rules_[k].selector, chain)) matched.push_back(&rules_[k]);
    }
    std::stable_sort(matched.begin(), matched.end(), [](const Rule* a, const Rule* b) {
      return a->selector.specificity != b->selector.specificity
                 ? a->selector.specificity < b->selector.specificity
                 : a->order < b->order;
    });
    for (const Rule* r : matched) {
      for (const Declaration& d : *r->declarations)
        (d.important ? important : normal)->push_back(&d);
    }
    return true;
  }

 private:
  struct Rule {
    Selector selector;
    std::shared_ptr<const std::vector<Declaration>> declarations;
    int order = 0;
  };

  static std::string StripComments(const std::string& s) {
    std::string out;
    out.reserve(s.size());
    size_t i = 0;
    while (i < s.size()) {
      if (s.compare(i, 2, "/*") == 0) {
        const size_t end = s.find("*/", i + 2);
        i = end == std::string::npos ? s.size() : end + 2;
        out += ' ';
      } else if (s.compare(i, 4, "<!--") == 0) {
        i += 4;
        out += ' ';
      } else if (s.compare(i, 3, "-->") == 0) {
        i += 3;
        out += ' ';
      } else {
        out += s[i++];
      }
    }
    return out;
  }

  // Index just past the '}' closing the block opened at s[open], or s.size().
  static size_t SkipBlock(const std::string& s, size_t open) {
    int depth = 0;
    char quote = 0;
    for (size_t j = open; j < s.size(); ++j) {
      const char c = s[j];
      if (quote != 0) {
        if (c == quote) quote = 0;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '{') {
        ++depth;
      } else if (c == '}' && --depth == 0) {
        return j + 1;
      }
    }
    return s.size();
  }

  void Add(Selector sel, std::shared_ptr<const std::vector<Declaration>> decls) {
    const int k = static_cast<int>(rules_.size());
    const Compound& key = sel.parts.back();
    if (!key.id.empty()) {
      by_id_[key.id].push_back(k);
    } else if (!key.classes.empty()) {
      by_class_[key.classes.front()].push_back(k);
    } else if (!key.type.empty() && key.type != "*") {
      by_type_[key.type].push_back(k);
    } else {
      universal_.push_back(k);
    }
    rules_.push_back(Rule{std::move(sel), std::move(decls), k});
  }

  std::vector<Rule> rules_;
  std::unordered_map<std::string, std::vector<int>> by_id_, by_class_, by_type_;
  std::vector<int> universal_;
  double work_ = 0;
};

// The properties that change what is marked. Each is also a presentation attribute.
bool IsProperty(std::string_view p) {
  static const char* const kProperties[] = {
      "fill",       "fill-opacity", "stroke",         "stroke-opacity", "display",
      "visibility", "opacity",      "font-family",    "font-size",      "font-weight",
      "font-style", "text-anchor",  "letter-spacing", "clip-path",      "mask",
      "filter",     "marker-start", "marker-mid",     "marker-end"};
  for (const char* k : kProperties) {
    if (p == k) return true;
  }
  return false;
}

using Properties = std::map<std::string, std::string>;

// The inherited properties, as computed for an element.
struct Style {
  bool fill_none = false;   // fill: none or transparent
  bool fill_clear = false;  // fill-opacity: 0
  std::string fill_server;  // the skipped kind of the gradient or pattern that fills it
  bool stroke_none = true;
  bool stroke_clear = false;
  bool stroke_given = false;  // stroke set anywhere above: a file that says stroke="none" means it
  bool visible = true;
  bool markers[3] = {false, false, false};  // marker-start, -mid, -end
  std::string font_family = "sans-serif";
  double font_size = 16.0;  // user units (CSS medium)
  bool bold = false, italic = false;
  TextAlign anchor = TextAlign::kLeft;
  double letter_spacing = 0.0;  // user units
  bool preserve_space = false;  // xml:space="preserve"

  bool FillNone() const { return fill_none || fill_clear; }
  // Neither filled nor stroked, as the file says in so many words.
  bool Unpainted() const { return FillNone() && stroke_given && (stroke_none || stroke_clear); }
};

// An element's style and the properties that are not inherited.
struct Computed {
  Style style;
  bool display_none = false;
  bool transparent = false;  // opacity: 0
  bool clip = false, mask = false, filter = false;
};

// Opacity values: a number or a percentage.
std::optional<double> ParseOpacity(const std::string& v) {
  const std::optional<Length> l = ParseLength(v);
  if (!l || (!l->unit.empty() && l->unit != "%")) return std::nullopt;
  return l->unit == "%" ? l->value / 100.0 : l->value;
}

struct TextRun {
  std::string text;
  Style style;
  std::optional<double> x, y;  // absolute position: starts a text chunk
  double dx = 0, dy = 0;
};

struct Glyphs {
  std::vector<Polyline> paths;  // user units, y down
  std::vector<bool> fill_none;
  int glyphs = 0;
};

class SvgReader {
 public:
  SvgReader(std::string origin, double tolerance_mm, const tinyxml2::XMLDocument& doc)
      : origin_(std::move(origin)), tol_(tolerance_mm) {
    // Ids (the first of a duplicate wins, as in browsers) and the style sheets, in document
    // order; iterative, though tinyxml2 bounds the depth.
    std::string css;
    std::vector<const XMLElement*> stack;
    if (doc.RootElement() != nullptr) stack.push_back(doc.RootElement());
    while (!stack.empty()) {
      const XMLElement* e = stack.back();
      stack.pop_back();
      if (const char* id = e->Attribute("id")) ids_.emplace(id, e);
      if (LocalName(e) == "style") {
        const char* type = e->Attribute("type");
        if (type == nullptr || Trim(type).empty() || Lower(Trim(type)) == "text/css") {
          for (const tinyxml2::XMLNode* n = e->FirstChild(); n != nullptr; n = n->NextSibling()) {
            if (n->ToText() != nullptr) css += n->Value();
          }
          css += '\n';
        } else {
          Warn(std::string("<style type=\"") + type + "\"> is not CSS: not applied");
        }
      }
      std::vector<const XMLElement*> children;
      for (const XMLElement* c = e->FirstChildElement(); c != nullptr;
           c = c->NextSiblingElement()) {
        children.push_back(c);
      }
      stack.insert(stack.end(), children.rbegin(), children.rend());
    }
    std::vector<std::string> css_warnings;
    sheet_.Parse(css, &css_warnings);
    for (const std::string& w : css_warnings) Warn(w);
  }

  // The root <svg>: `units` takes its user units to pattern mm (y up); `viewport` is its
  // size in user units, for percentages.
  Status Root(const XMLElement* root, const Affine& units, const Vec& viewport) {
    units_ = units;
    viewports_.push_back(viewport);
    const Computed c = Compute(Style{}, root);
    if (c.display_none || c.transparent) return Status::Ok();
    Affine t = Affine::Identity();
    if (const char* tr = root->Attribute("transform")) {
      INSITU_ASSIGN_OR_RETURN(t, ParseTransform(tr, Where(root)));
    }
    References(c);
    INSITU_RETURN_IF_ERROR(Children(root, c.style, t, 1));
    return css_status_;
  }

  VectorPattern Finish() {
    for (const std::string& w : warning_order_) {
      const int n = warning_counts_[w];
      out_.warnings.push_back(n > 1 ? w + " (" + std::to_string(n) + " times)" : w);
    }
    if (dropped_warnings_ > 0) {
      out_.warnings.push_back(std::to_string(dropped_warnings_) + " more warnings not listed");
    }
    return std::move(out_);
  }

 private:
  // Elements that are drawn only through a reference (or never): nothing of theirs is
  // marked where they stand.
  static bool IsNonRendering(const std::string& n) {
    static const char* const kNames[] = {
        "defs",           "symbol",         "title",      "desc",       "metadata",      "style",
        "linearGradient", "radialGradient", "pattern",    "clipPath",   "mask",          "marker",
        "filter",         "font",           "font-face",  "glyph",      "missing-glyph", "cursor",
        "view",           "color-profile",  "solidColor", "solidcolor", "meshgradient",  "hatch"};
    for (const char* k : kNames) {
      if (n == k) return true;
    }
    return false;
  }
  static bool IsAnimation(const std::string& n) {
    return n == "animate" || n == "animateTransform" || n == "animateMotion" ||
           n == "animateColor" || n == "set";
  }

  std::string Where(const XMLElement* e) const {
    const char* id = e->Attribute("id");
    return origin_ + ": <" + e->Name() + (id ? std::string(" id=\"") + id + "\"" : "") +
           "> (line " + std::to_string(e->GetLineNum()) + ")";
  }

  void Warn(const std::string& w) {
    auto it = warning_counts_.find(w);
    if (it != warning_counts_.end()) {
      ++it->second;
    } else if (warning_order_.size() < kMaxWarnings) {
      warning_counts_.emplace(w, 1);
      warning_order_.push_back(w);
    } else {
      ++dropped_warnings_;
    }
  }

  const XMLElement* Find(const std::string& id) const {
    const auto it = ids_.find(id);
    return it == ids_.end() ? nullptr : it->second;
  }

  // Presentation attributes, then CSS, then the style attribute, then !important CSS and
  // !important style declarations: each later one wins.
  const Properties& Declared(const XMLElement* e) {
    const auto it = declared_.find(e);
    if (it != declared_.end()) return it->second;
    Properties p;
    const auto set = [&p](const std::string& property, const std::string& value) {
      if (property == "marker") {
        p["marker-start"] = p["marker-mid"] = p["marker-end"] = value;
      } else if (IsProperty(property)) {
        p[property] = value;
      }
    };
    for (const tinyxml2::XMLAttribute* a = e->FirstAttribute(); a != nullptr; a = a->Next()) {
      if (IsProperty(a->Name())) p[a->Name()] = Trim(a->Value());
    }
    std::vector<const Declaration*> normal, important;
    if (!sheet_.Match(e, &normal, &important) && css_status_.ok()) {
      css_status_ = InvalidArgument(origin_ + ": the style sheet costs too much to apply (" +
                                    "more than 2 10^7 selector tests)");
    }
    std::vector<Declaration> inline_style;
    if (const char* s = e->Attribute("style")) inline_style = ParseDeclarations(s);
    for (const Declaration* d : normal) set(d->property, d->value);
    for (const Declaration& d : inline_style) {
      if (!d.important) set(d.property, d.value);
    }
    for (const Declaration* d : important) set(d->property, d->value);
    for (const Declaration& d : inline_style) {
      if (d.important) set(d.property, d.value);
    }
    return declared_.emplace(e, std::move(p)).first->second;
  }

  // fill or stroke: none, a colour, or url(#id) [fallback]. A reference to something that is
  // not a gradient or pattern paints the fallback, or nothing (SVG 2).
  void Paint(const std::string& value, const char* property, bool* none, std::string* server) {
    const std::string v = Lower(value);
    server->clear();
    if (StartsWith(v, "url(")) {
      const size_t close = value.find(')');
      std::string id =
          Trim(value.substr(4, close == std::string::npos ? std::string::npos : close - 4));
      if (id.size() >= 2 && (id.front() == '"' || id.front() == '\'') && id.back() == id.front()) {
        id = id.substr(1, id.size() - 2);
      }
      if (StartsWith(id, "#")) id.erase(0, 1);
      const std::string fallback =
          close == std::string::npos ? "" : Lower(Trim(std::string_view(value).substr(close + 1)));
      const XMLElement* ref = Find(id);
      const std::string kind = ref != nullptr ? LocalName(ref) : "";
      if (kind == "linearGradient" || kind == "radialGradient" || kind == "pattern") {
        *none = false;
        *server = kind == "pattern" ? "svg_pattern" : "svg_gradient";
      } else if (!fallback.empty()) {
        *none = fallback == "none" || fallback == "transparent";
      } else {
        Warn(std::string(property) + ": url(#" + id +
             ") is not a gradient or pattern of the file: " + "not painted");
        *none = true;
      }
      return;
    }
    *none = v == "none" || v == "transparent";
  }

  double ToUser(const Length& l, int axis, double font_size, bool* ok) const {
    *ok = true;
    if (l.unit == "em") return l.value * font_size;
    if (l.unit == "ex") return l.value * font_size / 2;
    if (l.unit == "%") {
      const Vec vp = viewports_.empty() ? Vec::Zero() : viewports_.back();
      const double ref = axis == 0 ? vp.x() : axis == 1 ? vp.y() : vp.norm() / std::sqrt(2.0);
      return l.value / 100.0 * ref;
    }
    const double px = PxPer(l.unit);
    *ok = px != 0;
    return l.value * px;
  }

  Computed Compute(const Style& parent, const XMLElement* e) {
    Computed c;
    c.style = parent;
    Style& s = c.style;
    if (const char* space = e->Attribute("xml:space"))
      s.preserve_space = std::string(space) == "preserve";
    const Properties& p = Declared(e);
    const auto get = [&p](const char* name) -> const std::string* {
      const auto it = p.find(name);
      return it == p.end() || it->second == "inherit" ? nullptr : &it->second;
    };
    if (const std::string* v = get("font-size")) {
      const std::string k = Lower(*v);
      static const std::pair<const char*, double> kSizes[] = {
          {"xx-small", 9}, {"x-small", 10}, {"small", 13},   {"medium", 16},
          {"large", 18},   {"x-large", 24}, {"xx-large", 32}};
      bool done = false;
      for (const auto& [name, px] : kSizes) {
        if (k == name) s.font_size = px, done = true;
      }
      if (k == "larger") s.font_size = parent.font_size * 1.2, done = true;
      if (k == "smaller") s.font_size = parent.font_size / 1.2, done = true;
      if (!done) {
        if (const std::optional<Length> l = ParseLength(k)) {
          bool ok = false;
          const double size = l->unit == "%" ? l->value / 100.0 * parent.font_size
                                             : ToUser(*l, 2, parent.font_size, &ok);
          if ((ok || l->unit == "%") && size > 0 && std::isfinite(size)) s.font_size = size;
        }
      }
    }
    for (const auto& [name, value] : p) {
      if (value == "inherit" || name == "font-size") continue;
      const std::string v = Lower(value);
      if (name == "fill") {
        Paint(value, "fill", &s.fill_none, &s.fill_server);
      } else if (name == "stroke") {
        std::string server;
        Paint(value, "stroke", &s.stroke_none, &server);
        s.stroke_given = true;
      } else if (name == "fill-opacity" || name == "stroke-opacity") {
        if (const std::optional<double> o = ParseOpacity(v)) {
          (name == "fill-opacity" ? s.fill_clear : s.stroke_clear) = *o <= 0;
        }
      } else if (name == "opacity") {
        if (const std::optional<double> o = ParseOpacity(v)) c.transparent = *o <= 0;
      } else if (name == "display") {
        c.display_none = v == "none";
      } else if (name == "visibility") {
        if (v == "hidden" || v == "collapse") s.visible = false;
        if (v == "visible") s.visible = true;
      } else if (name == "font-family") {
        s.font_family = value;
      } else if (name == "font-weight") {
        if (v == "bold" || v == "bolder") s.bold = true;
        if (v == "normal" || v == "lighter") s.bold = false;
        if (const std::optional<Length> l = ParseLength(v); l && l->unit.empty())
          s.bold = l->value >= 600;
      } else if (name == "font-style") {
        s.italic = v == "italic" || v == "oblique";
      } else if (name == "text-anchor") {
        if (v == "start") s.anchor = TextAlign::kLeft;
        if (v == "middle") s.anchor = TextAlign::kCenter;
        if (v == "end") s.anchor = TextAlign::kRight;
      } else if (name == "letter-spacing") {
        if (v == "normal") s.letter_spacing = 0;
        if (const std::optional<Length> l = ParseLength(v)) {
          bool ok = false;
          const double ls = ToUser(*l, 0, s.font_size, &ok);
          if (ok && std::isfinite(ls)) s.letter_spacing = ls;
        }
      } else if (name == "clip-path" || name == "mask" || name == "filter") {
        (name == "clip-path" ? c.clip : name == "mask" ? c.mask : c.filter) = StartsWith(v, "url(");
      } else if (StartsWith(name, "marker-")) {
        const int k = name == "marker-start" ? 0 : name == "marker-mid" ? 1 : 2;
        s.markers[k] = StartsWith(v, "url(");
      }
    }
    return c;
  }

  // The element's clip path, mask and filter: not applied, counted and explained.
  void References(const Computed& c) {
    if (c.clip) {
      ++out_.skipped["svg_clip_path"];
      Warn("clip-path is not applied: clipped elements are marked whole");
    }
    if (c.mask) {
      ++out_.skipped["svg_mask"];
      Warn("mask is not applied: masked elements are marked whole");
    }
    if (c.filter) {
      ++out_.skipped["svg_filter"];
      Warn("filter effects are not applied: filtered elements are marked as their geometry");
    }
  }

  Status Children(const XMLElement* e, const Style& style, const Affine& t, int depth) {
    for (const XMLElement* c = e->FirstChildElement(); c != nullptr; c = c->NextSiblingElement()) {
      INSITU_RETURN_IF_ERROR(Draw(c, style, t, depth));
    }
    return Status::Ok();
  }

  Status Draw(const XMLElement* e, const Style& parent, const Affine& t, int depth) {
    const std::string name = LocalName(e);
    if (name.empty() || IsNonRendering(name)) return Status::Ok();
    if (++elements_ > kMaxElements) {
      return InvalidArgument(origin_ + ": more than " + std::to_string(kMaxElements) +
                             " elements to draw once <use> is expanded");
    }
    if (depth > kMaxDepth) {
      return InvalidArgument(Where(e) + ": elements nested deeper than " +
                             std::to_string(kMaxDepth) + " (with <use> expanded)");
    }
    if (name == "image" || name == "foreignObject" || IsAnimation(name) || name == "flowRoot") {
      const char* kind = name == "image"           ? "svg_image"
                         : name == "foreignObject" ? "svg_foreign_object"
                         : name == "flowRoot"      ? "svg_flowed_text"
                                                   : "svg_animation";
      ++out_.skipped[kind];
      if (name == "flowRoot") {
        Warn(
            "flowed text (<flowRoot>, Inkscape 0.92) is not SVG 1.1 and is not drawn: convert it "
            "with Inkscape's Text > Convert to Text");
      }
      return Status::Ok();
    }
    static const char* const kDrawn[] = {"g",        "a",       "svg",    "switch",  "use",
                                         "path",     "rect",    "circle", "ellipse", "line",
                                         "polyline", "polygon", "text"};
    if (std::none_of(std::begin(kDrawn), std::end(kDrawn),
                     [&](const char* k) { return name == k; })) {
      ++out_.skipped["svg_unknown_element"];
      Warn("<" + name + "> is not an element insitu draws: not drawn");
      return Status::Ok();
    }
    const std::string where = Where(e);
    const Computed c = Compute(parent, e);
    INSITU_RETURN_IF_ERROR(css_status_);
    if (c.display_none || c.transparent) {
      ++out_.skipped["svg_hidden"];
      return Status::Ok();
    }
    Affine tt = t;
    if (const char* tr = e->Attribute("transform")) {
      INSITU_ASSIGN_OR_RETURN(const Affine m, ParseTransform(tr, where));
      tt = t * m;
    }
    References(c);
    if (name == "g" || name == "a") return Children(e, c.style, tt, depth + 1);
    if (name == "svg") {
      double x = 0, y = 0, w = 0, h = 0;
      INSITU_RETURN_IF_ERROR(Len(e, "x", 0, c.style, 0.0, &x, where));
      INSITU_RETURN_IF_ERROR(Len(e, "y", 1, c.style, 0.0, &y, where));
      INSITU_RETURN_IF_ERROR(Len(e, "width", 0, c.style, FullExtent(e, 0), &w, where));
      INSITU_RETURN_IF_ERROR(Len(e, "height", 1, c.style, FullExtent(e, 1), &h, where));
      return ViewportContent(e, c.style, tt * Eigen::Translation2d(x, y), w, h, depth, where);
    }
    if (name == "switch") {
      bool taken = false;
      for (const XMLElement* k = e->FirstChildElement(); k != nullptr;
           k = k->NextSiblingElement()) {
        const std::string kn = LocalName(k);
        if (kn.empty() || kn == "title" || kn == "desc" || kn == "metadata") continue;
        // No extension is supported; features and languages are taken as met.
        const char* features = k->Attribute("requiredFeatures");
        const bool eligible = k->Attribute("requiredExtensions") == nullptr &&
                              (features == nullptr ||
                               std::string(features).find("Extensibility") == std::string::npos);
        if (!taken && eligible) {
          taken = true;
          INSITU_RETURN_IF_ERROR(Draw(k, c.style, tt, depth + 1));
        } else {
          ++out_.skipped["svg_switch"];
        }
      }
      return Status::Ok();
    }
    if (name == "use") return Use(e, c, tt, depth, where);
    if (name == "text") return Text(e, c.style, tt, where);
    if (!c.style.visible) {
      ++out_.skipped["svg_hidden"];
      return Status::Ok();
    }
    if (c.style.Unpainted()) {
      ++out_.skipped["svg_unpainted"];
      return Status::Ok();
    }
    for (const XMLElement* k = e->FirstChildElement(); k != nullptr; k = k->NextSiblingElement()) {
      if (IsAnimation(LocalName(k))) ++out_.skipped["svg_animation"];
    }
    tf_ = tt;
    fill_none_ = c.style.FillNone();
    const size_t before = out_.paths.size();
    INSITU_RETURN_IF_ERROR(Shape(e, name, c.style, where));
    INSITU_RETURN_IF_ERROR(Check(where));
    if (out_.paths.size() == before) return Status::Ok();
    ++out_.converted[name];
    if (!c.style.FillNone() && !c.style.fill_server.empty()) {
      ++out_.skipped[c.style.fill_server];
      Warn("gradient and pattern fills are not marked as shading: their areas are hatched plain");
    }
    if (c.style.markers[0] || c.style.markers[1] || c.style.markers[2]) {
      ++out_.skipped["svg_marker"];
      Warn("markers (arrowheads, dots on vertices) are not drawn");
    }
    return Status::Ok();
  }

  Vec Viewport() const { return viewports_.empty() ? Vec::Zero() : viewports_.back(); }

  // 100 % of the viewport along an axis, for a viewport element without width or height; in
  // a root without any size, the element's own viewBox at 1:1.
  double FullExtent(const XMLElement* e, int axis) const {
    const double full = Viewport()[axis];
    if (full > 0) return full;
    double vb[4];
    const char* text = e->Attribute("viewBox");
    return text != nullptr && ParseViewBox(text, vb) ? vb[2 + axis] : 0.0;
  }

  // A length attribute in user units; `fallback` when absent or "auto". axis 0: x, 1: y,
  // 2: other (percentages of the viewport's diagonal / sqrt 2).
  Status Len(const XMLElement* e, const char* attr, int axis, const Style& style, double fallback,
             double* out, const std::string& where) const {
    *out = fallback;
    const char* text = e->Attribute(attr);
    if (text == nullptr || Trim(text).empty() || Trim(text) == "auto") return Status::Ok();
    bool ok = false;
    const std::optional<Length> l = ParseLength(text);
    if (l) *out = ToUser(*l, axis, style.font_size, &ok);
    if (!ok || !std::isfinite(*out)) {
      return ParseError(where + ": " + attr + "=\"" + text + "\" is not a length");
    }
    return Status::Ok();
  }

  // The first of a list of lengths (text x, y, dx, dy); nullopt when absent.
  Result<std::optional<double>> FirstLen(const XMLElement* e, const char* attr, int axis,
                                         const Style& style, const std::string& where) {
    const char* text = e->Attribute(attr);
    if (text == nullptr) return std::optional<double>();
    std::vector<std::string> items;
    std::string item;
    for (const char* c = text; *c; ++c) {
      if (IsSpace(*c) || *c == ',') {
        if (!item.empty()) items.push_back(item);
        item.clear();
      } else {
        item += *c;
      }
    }
    if (!item.empty()) items.push_back(item);
    if (items.empty()) return std::optional<double>();
    if (items.size() > 1) {
      Warn(std::string("text ") + attr +
           " lists a position per letter: the text is set from the "
           "first one");
    }
    bool ok = false;
    const std::optional<Length> l = ParseLength(items[0]);
    double v = 0;
    if (l) v = ToUser(*l, axis, style.font_size, &ok);
    if (!ok || !std::isfinite(v)) {
      return ParseError(where + ": " + attr + "=\"" + text + "\" is not a length");
    }
    return std::optional<double>(v);
  }

  // A new viewport of w x h user units at the origin of `t` (nested <svg>, or the <svg> or
  // <symbol> a <use> draws), its viewBox onto it.
  Status ViewportContent(const XMLElement* e, const Style& style, const Affine& t, double w,
                         double h, int depth, const std::string& where) {
    if (!(w > 0 && h > 0)) {
      ++out_.skipped["svg_degenerate"];
      return Status::Ok();
    }
    Affine m = t;
    Vec size(w, h);
    if (const char* vb = e->Attribute("viewBox")) {
      double v[4];
      if (!ParseViewBox(vb, v)) {
        return ParseError(where + ": viewBox must be four numbers, width and height > 0");
      }
      m = t * ViewBoxTransform(v, w, h, e->Attribute("preserveAspectRatio"));
      size = Vec(v[2], v[3]);
    }
    viewports_.push_back(size);
    const Status s = Children(e, style, m, depth + 1);
    viewports_.pop_back();
    return s;
  }

  static std::string Href(const XMLElement* e) {
    if (const char* h = e->Attribute("href")) return Trim(h);
    for (const tinyxml2::XMLAttribute* a = e->FirstAttribute(); a != nullptr; a = a->Next()) {
      const std::string_view n = a->Name();
      if (n.size() > 5 && n.substr(n.size() - 5) == ":href") return Trim(a->Value());
    }
    return "";
  }

  Status Use(const XMLElement* e, const Computed& c, const Affine& t, int depth,
             const std::string& where) {
    const std::string href = Href(e);
    const auto skip = [&](const std::string& why) {
      ++out_.skipped["svg_use"];
      Warn(where + ": " + why + ": not drawn");
      return Status::Ok();
    };
    if (href.empty()) return skip("no href");
    if (href[0] != '#') return skip("href=\"" + href + "\" is in another file");
    const XMLElement* target = Find(href.substr(1));
    if (target == nullptr) return skip("href=\"" + href + "\" names no element of the file");
    for (const XMLElement* a = e; a != nullptr; a = ParentElement(a)) {
      if (a == target) return skip("href=\"" + href + "\" names an element that holds the <use>");
    }
    if (std::find(use_stack_.begin(), use_stack_.end(), target) != use_stack_.end()) {
      return skip("href=\"" + href + "\" comes back to itself through other <use> elements");
    }
    if (static_cast<int>(use_stack_.size()) >= kMaxUseDepth) {
      return skip("<use> nested deeper than " + std::to_string(kMaxUseDepth));
    }
    double x = 0, y = 0;
    INSITU_RETURN_IF_ERROR(Len(e, "x", 0, c.style, 0.0, &x, where));
    INSITU_RETURN_IF_ERROR(Len(e, "y", 1, c.style, 0.0, &y, where));
    const Affine m = t * Eigen::Translation2d(x, y);
    ++out_.converted["use"];
    use_stack_.push_back(target);
    Status s;
    const std::string kind = LocalName(target);
    if (kind == "symbol" || kind == "svg") {
      // The <use>'s width and height, else the target's own, else 100 %.
      const std::string twhere = Where(target);
      double w = 0, h = 0;
      s = Len(target, "width", 0, c.style, FullExtent(target, 0), &w, twhere);
      if (s.ok()) s = Len(target, "height", 1, c.style, FullExtent(target, 1), &h, twhere);
      if (s.ok()) s = Len(e, "width", 0, c.style, w, &w, where);
      if (s.ok()) s = Len(e, "height", 1, c.style, h, &h, where);
      if (s.ok()) s = ReferencedViewport(target, c.style, m, w, h, depth + 1);
    } else {
      s = Draw(target, c.style, m, depth + 1);
    }
    use_stack_.pop_back();
    return s;
  }

  Status ReferencedViewport(const XMLElement* target, const Style& parent, const Affine& t,
                            double w, double h, int depth) {
    if (++elements_ > kMaxElements) {
      return InvalidArgument(origin_ + ": more than " + std::to_string(kMaxElements) +
                             " elements to draw once <use> is expanded");
    }
    const std::string where = Where(target);
    const Computed c = Compute(parent, target);
    if (c.display_none || c.transparent) {
      ++out_.skipped["svg_hidden"];
      return Status::Ok();
    }
    References(c);
    return ViewportContent(target, c.style, t, w, h, depth, where);
  }

  // Coordinates that overflowed a double, or a file that flattens to more points than a
  // marking can hold.
  Status Check(const std::string& where) {
    if (bad_coordinates_)
      return InvalidArgument(where + ": coordinates out of range after the transforms");
    if (points_ > kMaxPoints) {
      return InvalidArgument(origin_ + ": more than " + std::to_string(kMaxPoints) +
                             " points once flattened");
    }
    return Status::Ok();
  }

  Status Shape(const XMLElement* e, const std::string& name, const Style& style,
               const std::string& where) {
    const auto len = [&](const char* attr, int axis, double* v) {
      return Len(e, attr, axis, style, 0.0, v, where);
    };
    if (name == "path") return Path(e->Attribute("d") ? e->Attribute("d") : "", where);
    if (name == "line") {
      double x1, y1, x2, y2;
      INSITU_RETURN_IF_ERROR(len("x1", 0, &x1));
      INSITU_RETURN_IF_ERROR(len("y1", 1, &y1));
      INSITU_RETURN_IF_ERROR(len("x2", 0, &x2));
      INSITU_RETURN_IF_ERROR(len("y2", 1, &y2));
      Begin({x1, y1});
      Line({x2, y2});
      End(false);
      return Status::Ok();
    }
    if (name == "polyline" || name == "polygon") {
      NumberReader r(e->Attribute("points") ? e->Attribute("points") : "");
      std::vector<double> v;
      double x;
      while (r.Number(&x)) v.push_back(x);
      if (!r.Done() || v.size() % 2 != 0 || v.size() < 4) {
        return ParseError(where + ": points must be at least two x,y pairs");
      }
      Begin({v[0], v[1]});
      for (size_t k = 2; k < v.size(); k += 2) Line({v[k], v[k + 1]});
      End(name == "polygon");
      return Status::Ok();
    }
    if (name == "rect") {
      double x, y, w, h, rx = -1, ry = -1;
      INSITU_RETURN_IF_ERROR(len("x", 0, &x));
      INSITU_RETURN_IF_ERROR(len("y", 1, &y));
      INSITU_RETURN_IF_ERROR(len("width", 0, &w));
      INSITU_RETURN_IF_ERROR(len("height", 1, &h));
      INSITU_RETURN_IF_ERROR(Len(e, "rx", 0, style, -1.0, &rx, where));
      INSITU_RETURN_IF_ERROR(Len(e, "ry", 1, style, -1.0, &ry, where));
      if (w < 0 || h < 0) return ParseError(where + ": width and height must not be negative");
      if (w == 0 || h == 0) {
        ++out_.skipped["svg_degenerate"];
        return Status::Ok();
      }
      // SVG 1.1 rect: one radius given means both; each at most half the side.
      if (rx < 0) rx = ry;
      if (ry < 0) ry = rx;
      rx = std::clamp(rx, 0.0, w / 2);
      ry = std::clamp(ry, 0.0, h / 2);
      if (rx == 0 || ry == 0) {
        Begin({x, y});
        Line({x + w, y});
        Line({x + w, y + h});
        Line({x, y + h});
        End(true);
        return Status::Ok();
      }
      Begin({x + rx, y});
      Line({x + w - rx, y});
      EllipseArc({x + w - rx, y + ry}, rx, ry, -M_PI / 2, 0);
      Line({x + w, y + h - ry});
      EllipseArc({x + w - rx, y + h - ry}, rx, ry, 0, M_PI / 2);
      Line({x + rx, y + h});
      EllipseArc({x + rx, y + h - ry}, rx, ry, M_PI / 2, M_PI);
      Line({x, y + ry});
      EllipseArc({x + rx, y + ry}, rx, ry, M_PI, 1.5 * M_PI);
      End(true);
      return Status::Ok();
    }
    if (name == "circle" || name == "ellipse") {
      double cx, cy, rx = -1, ry = -1;
      INSITU_RETURN_IF_ERROR(len("cx", 0, &cx));
      INSITU_RETURN_IF_ERROR(len("cy", 1, &cy));
      if (name == "circle") {
        INSITU_RETURN_IF_ERROR(Len(e, "r", 2, style, 0.0, &rx, where));
        ry = rx;
      } else {
        INSITU_RETURN_IF_ERROR(Len(e, "rx", 0, style, -1.0, &rx, where));
        INSITU_RETURN_IF_ERROR(Len(e, "ry", 1, style, -1.0, &ry, where));
        if (rx < 0) rx = ry;  // SVG 2: an auto radius is the other one
        if (ry < 0) ry = rx;
      }
      if (rx < 0 || ry < 0) return ParseError(where + ": radius must not be negative");
      if (rx == 0 || ry == 0) {
        ++out_.skipped["svg_degenerate"];
        return Status::Ok();
      }
      Begin({cx + rx, cy});
      EllipseArc({cx, cy}, rx, ry, 0, 2 * M_PI);
      End(true);
      return Status::Ok();
    }
    return Status::Ok();
  }

  // Text: its runs of characters (the <text> and its <tspan>s, each with its style), set in
  // chunks (a chunk starts at each absolute x or y) by RenderText, glyph outlines placed on the
  // baseline at the chunk's position and anchored by its text-anchor. Runs are set one by one;
  // where a run must be placed after another, the first's advance is measured as the width it
  // adds in front of an "H" (ink of "run" + "H" minus ink of "H"), RenderText giving outlines,
  // not metrics.
  Status Text(const XMLElement* e, const Style& style, const Affine& t, const std::string& where) {
    std::vector<TextRun> runs;
    INSITU_RETURN_IF_ERROR(CollectText(e, style, where, &runs));
    CollapseSpaces(&runs);
    MergeRuns(&runs);
    if (e->Attribute("rotate") != nullptr) Warn("text rotate (per letter) is not applied");
    if (e->Attribute("textLength") != nullptr) Warn("text textLength is not applied");
    const auto inked = [](const TextRun& r) {
      return r.text.find_first_not_of(' ') != std::string::npos;
    };
    if (std::none_of(runs.begin(), runs.end(), inked)) return Status::Ok();  // empty text
    const auto drawn = [&](const TextRun& r) {
      return inked(r) && r.style.visible && !r.style.Unpainted();
    };
    if (std::none_of(runs.begin(), runs.end(), drawn)) {
      const bool hidden = std::any_of(
          runs.begin(), runs.end(), [&](const TextRun& r) { return inked(r) && !r.style.visible; });
      ++out_.skipped[hidden ? "svg_hidden" : "svg_unpainted"];
      return Status::Ok();
    }
    tf_ = t;
    const double scale = Scale();
    if (!(scale > 0) || !std::isfinite(scale)) return Status::Ok();  // scaled to nothing
    const double tol = tol_ / scale;
    for (const TextRun& r : runs) {
      if (inked(r) && !(r.style.font_size * scale <= kMaxFontMm)) {
        ++out_.skipped["svg_text"];
        Warn(where + ": text not drawn: its em is " + std::to_string(r.style.font_size * scale) +
             " mm");
        return Status::Ok();
      }
    }
    Glyphs glyphs;
    Status failure;
    Vec pen = Vec::Zero();
    for (size_t i = 0; i < runs.size() && failure.ok();) {
      size_t j = i + 1;
      while (j < runs.size() && !runs[j].x && !runs[j].y) ++j;
      const TextAlign anchor = runs[i].style.anchor;
      const bool next_continues = j < runs.size() && !runs[j].x;
      Vec p = pen;
      if (runs[i].x) p.x() = *runs[i].x;
      if (runs[i].y) p.y() = *runs[i].y;
      const Vec start = p;
      std::vector<Vec> origins;
      for (size_t k = i; k < j && failure.ok(); ++k) {
        p += Vec(runs[k].dx, runs[k].dy);
        origins.push_back(p);
        const bool has_text = !runs[k].text.empty();
        if (has_text && (k + 1 < j || anchor != TextAlign::kLeft || next_continues)) {
          const Result<double> a = Advance(runs[k], tol);
          if (!a.ok())
            failure = a.status();
          else
            p.x() += *a;
        }
      }
      const double width = p.x() - start.x();
      const double shift = anchor == TextAlign::kCenter  ? -width / 2
                           : anchor == TextAlign::kRight ? -width
                                                         : 0.0;
      for (size_t k = i; k < j && failure.ok(); ++k) {
        const TextRun& r = runs[k];
        if (!drawn(r)) continue;
        failure = SetRun(r, origins[k - i] + Vec(shift, 0), tol, &glyphs);
      }
      pen = p;
      i = j;
    }
    if (!failure.ok()) {
      ++out_.skipped["svg_text"];
      Warn(where + ": text not drawn: " + failure.message());
      return Status::Ok();
    }
    if (glyphs.paths.empty()) return Status::Ok();
    for (size_t k = 0; k < glyphs.paths.size(); ++k) {
      const Polyline& g = glyphs.paths[k];
      fill_none_ = glyphs.fill_none[k];
      if (g.points.size() < 2) continue;
      Begin(g.points[0]);
      for (size_t q = 1; q < g.points.size(); ++q) Line(g.points[q]);
      End(g.closed);
    }
    INSITU_RETURN_IF_ERROR(Check(where));
    ++out_.converted["text"];
    out_.converted["glyph"] += glyphs.glyphs;
    ++out_.texts;
    return Status::Ok();
  }

  // The runs of a <text> or <tspan>: its own characters, each child <tspan>'s, and its own
  // again after each child.
  Status CollectText(const XMLElement* e, const Style& style, const std::string& where,
                     std::vector<TextRun>* runs) {
    if (++elements_ > kMaxElements) {
      return InvalidArgument(origin_ + ": more than " + std::to_string(kMaxElements) +
                             " elements to draw once <use> is expanded");
    }
    TextRun first;
    first.style = style;
    INSITU_ASSIGN_OR_RETURN(first.x, FirstLen(e, "x", 0, style, where));
    INSITU_ASSIGN_OR_RETURN(first.y, FirstLen(e, "y", 1, style, where));
    INSITU_ASSIGN_OR_RETURN(const std::optional<double> dx, FirstLen(e, "dx", 0, style, where));
    INSITU_ASSIGN_OR_RETURN(const std::optional<double> dy, FirstLen(e, "dy", 1, style, where));
    first.dx = dx.value_or(0.0);
    first.dy = dy.value_or(0.0);
    runs->push_back(std::move(first));
    for (const tinyxml2::XMLNode* n = e->FirstChild(); n != nullptr; n = n->NextSibling()) {
      if (n->ToText() != nullptr) {
        runs->back().text += n->Value();
        continue;
      }
      const XMLElement* c = n->ToElement();
      if (c == nullptr) continue;
      const std::string name = LocalName(c);
      if (name == "tspan" || name == "a") {
        const Computed cc = Compute(style, c);
        if (cc.display_none || cc.transparent) {
          ++out_.skipped["svg_hidden"];
          continue;
        }
        References(cc);
        INSITU_RETURN_IF_ERROR(CollectText(c, cc.style, Where(c), runs));
        TextRun rest;
        rest.style = style;
        runs->push_back(std::move(rest));
      } else if (name == "textPath" || name == "tref") {
        ++out_.skipped[name == "textPath" ? "svg_text_path" : "svg_tref"];
      } else if (!name.empty() && name != "title" && name != "desc" && name != "metadata" &&
                 !IsAnimation(name)) {
        ++out_.skipped["svg_unknown_element"];
        Warn("<" + name + "> is not an element insitu draws inside text: not drawn");
      }
    }
    return Status::Ok();
  }

  // XML whitespace as SVG sets it: newlines and tabs are spaces; without xml:space="preserve"
  // runs of spaces are one, and none leads or trails a chunk.
  static void CollapseSpaces(std::vector<TextRun>* runs) {
    bool after_space = true;
    for (TextRun& r : *runs) {
      if (r.x || r.y) after_space = true;
      std::string out;
      for (char ch : r.text) {
        const char c = ch == '\n' || ch == '\r' || ch == '\t' ? ' ' : ch;
        if (c == ' ' && after_space && !r.style.preserve_space) continue;
        out += c;
        after_space = c == ' ';
      }
      r.text = std::move(out);
    }
    for (size_t i = 0; i < runs->size(); ++i) {
      const bool chunk_end = i + 1 == runs->size() || (*runs)[i + 1].x || (*runs)[i + 1].y;
      if (!chunk_end) continue;
      for (size_t k = i + 1; k-- > 0;) {
        TextRun& r = (*runs)[k];
        if (r.style.preserve_space) break;
        while (!r.text.empty() && r.text.back() == ' ') r.text.pop_back();
        if (!r.text.empty() || r.x || r.y) break;
      }
    }
  }

  // Neighbouring runs that look the same are set as one (kerning across them, fewer calls).
  static void MergeRuns(std::vector<TextRun>* runs) {
    std::vector<TextRun> out;
    for (TextRun& r : *runs) {
      if (!out.empty() && !r.x && !r.y && r.dx == 0 && r.dy == 0) {
        const Style& a = out.back().style;
        const Style& b = r.style;
        if (a.font_family == b.font_family && a.font_size == b.font_size && a.bold == b.bold &&
            a.italic == b.italic && a.letter_spacing == b.letter_spacing &&
            a.visible == b.visible && a.FillNone() == b.FillNone() &&
            a.Unpainted() == b.Unpainted()) {
          out.back().text += r.text;
          continue;
        }
      }
      out.push_back(std::move(r));
    }
    *runs = std::move(out);
  }

  // fontconfig pattern syntax: '-', ':', ',' and '\' are escaped in a family name.
  static std::string EscapeFamily(const std::string& family) {
    std::string out;
    for (char c : family) {
      if (c == '\\' || c == '-' || c == ':' || c == ',') out += '\\';
      out += c;
    }
    return out;
  }

  // The first family of the CSS list that fontconfig has (RenderText sets a probe "H" without
  // a warning), else the first, for RenderText to replace and warn about. "hershey:NAME" asks
  // for a single-stroke font.
  std::string Font(const Style& s) {
    std::vector<std::string> families;
    std::string cur;
    char quote = 0;
    for (char c : s.font_family) {
      if (quote != 0) {
        if (c == quote)
          quote = 0;
        else
          cur += c;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == ',') {
        families.push_back(Trim(cur));
        cur.clear();
      } else {
        cur += c;
      }
    }
    families.push_back(Trim(cur));
    families.erase(std::remove(families.begin(), families.end(), std::string()), families.end());
    if (families.empty()) families.push_back("sans-serif");
    const std::string suffix = std::string(s.bold ? ":bold" : "") + (s.italic ? ":italic" : "");
    const auto pattern = [&](const std::string& f) {
      return StartsWith(Lower(f), "hershey:") ? f : EscapeFamily(f) + suffix;
    };
    if (families.size() == 1) return pattern(families[0]);
    for (const std::string& f : families) {
      const std::string p = pattern(f);
      auto it = font_found_.find(p);
      if (it == font_found_.end()) {
        TextStyle probe;
        probe.font = p;
        probe.height_mm = 10;
        const Result<VectorPattern> r = RenderText("H", probe, 0.05);
        it = font_found_.emplace(p, r.ok() && r->warnings.empty()).first;
      }
      if (it->second) return p;
    }
    return pattern(families[0]);
  }

  TextStyle RunStyle(const TextRun& r) {
    TextStyle ts;
    ts.font = Font(r.style);
    ts.height_mm = r.style.font_size;  // user units: the glyphs are placed in user space
    ts.size_is_em = true;
    ts.letter_spacing_mm = r.style.letter_spacing;
    ts.align = TextAlign::kLeft;
    return ts;
  }

  static double MaxX(const VectorPattern& p) {
    double x = -INFINITY;
    for (const Polyline& l : p.paths) {
      for (const Vec& q : l.points) x = std::max(x, q.x());
    }
    return x;
  }

  Result<double> Advance(const TextRun& r, double tol) {
    const TextStyle ts = RunStyle(r);
    INSITU_ASSIGN_OR_RETURN(const VectorPattern with, RenderText(r.text + "H", ts, tol));
    INSITU_ASSIGN_OR_RETURN(const VectorPattern h, RenderText("H", ts, tol));
    const double a = MaxX(with) - MaxX(h);
    return std::isfinite(a) ? a : 0.0;
  }

  Status SetRun(const TextRun& r, const Vec& origin, double tol, Glyphs* out) {
    INSITU_ASSIGN_OR_RETURN(const VectorPattern p, RenderText(r.text, RunStyle(r), tol));
    for (const std::string& w : p.warnings) Warn(w);
    const auto g = p.converted.find("glyph");
    if (g != p.converted.end()) out->glyphs += g->second;
    for (const Polyline& l : p.paths) {
      Polyline q;
      q.closed = l.closed;
      q.points.reserve(l.points.size());
      // RenderText's y is up, the baseline on y = 0; user space's y is down.
      for (const Vec& v : l.points) q.points.push_back(origin + Vec(v.x(), -v.y()));
      out->paths.push_back(std::move(q));
      out->fill_none.push_back(r.style.FillNone());
    }
    return Status::Ok();
  }

  // The largest stretch of user units into mm under the current transform: the largest
  // singular value of its linear part, which bounds how far a chord's error grows.
  double Scale() const {
    const Eigen::Matrix2d m = (units_ * tf_).linear();
    const double f = m.squaredNorm(), d = m.determinant();
    return std::sqrt(0.5 * (f + std::sqrt(std::max(0.0, f * f - 4 * d * d))));
  }
  // Chords of an arc of radius r (user units) within the tolerance: sagitta r (1 - cos(a/2)).
  int Segments(double r_user, double angle) const {
    return ArcChords(r_user * Scale(), angle, tol_, 4);
  }
  void Begin(const Vec& p) {
    End(false);
    Line(p);
  }
  void Line(const Vec& p) {
    const Vec q = units_ * tf_ * p;
    if (!std::isfinite(q.x()) || !std::isfinite(q.y())) {
      bad_coordinates_ = true;
      return;
    }
    if (!current_.points.empty() && (current_.points.back() - q).norm() < 1e-12) return;
    if (++points_ > kMaxPoints) return;
    current_.points.push_back(q);
  }
  void End(bool closed) {
    if (current_.points.size() >= 2) {
      if (closed && (current_.points.front() - current_.points.back()).norm() < 1e-9) {
        current_.points.pop_back();
      }
      if (closed && fill_none_) {
        // fill none: an outline to follow, not an area to hatch.
        current_.points.push_back(current_.points.front());
      } else {
        current_.closed = closed && current_.points.size() >= 3;
      }
      out_.paths.push_back(std::move(current_));
    }
    current_ = Polyline{};
  }
  // Points of the ellipse c + (rx cos a, ry sin a) for a in (a0, a1], axis-aligned in user
  // space (the transform may turn it).
  void EllipseArc(const Vec& c, double rx, double ry, double a0, double a1) {
    const int n = Segments(std::max(rx, ry), a1 - a0);
    for (int k = 1; k <= n; ++k) {
      const double a = a0 + (a1 - a0) * k / n;
      Line(c + Vec(rx * std::cos(a), ry * std::sin(a)));
    }
  }
  void Cubic(const Vec& p0, const Vec& p1, const Vec& p2, const Vec& p3) {
    const double length = (p1 - p0).norm() + (p2 - p1).norm() + (p3 - p2).norm();
    const double scale = Scale();
    // Flatness of a cubic: max deviation <= 3/4 max(|second differences|) / n^2. At most one
    // chord per micrometre, and a bound that keeps a garbage file's work finite.
    const double dd = std::max((p0 - 2 * p1 + p2).norm(), (p1 - 2 * p2 + p3).norm()) * scale;
    const double n_flat = std::ceil(std::sqrt(0.75 * dd / tol_));
    const double n_len = std::max(1.0, length * scale / 0.001);
    const double nd = std::clamp(std::min(n_flat, n_len), 1.0, 100000.0);
    const int n = std::isfinite(nd) ? static_cast<int>(nd) : 1;
    for (int k = 1; k <= n; ++k) {
      const double t = static_cast<double>(k) / n, u = 1 - t;
      Line(u * u * u * p0 + 3 * u * u * t * p1 + 3 * u * t * t * p2 + t * t * t * p3);
    }
  }
  // SVG arc (endpoint parameterisation, SVG 1.1 implementation notes F.6.5 and F.6.6: radii
  // too small for the endpoints are scaled up by sqrt(lambda)).
  void Arc(const Vec& p0, double rx, double ry, double phi_deg, bool large, bool sweep,
           const Vec& p1) {
    if ((p1 - p0).norm() < 1e-12) return;  // F.6.2: same endpoints, no arc
    rx = std::abs(rx);
    ry = std::abs(ry);
    if (rx < 1e-12 || ry < 1e-12) {  // F.6.2: a zero radius is a line
      Line(p1);
      return;
    }
    const double phi = std::fmod(phi_deg, 360.0) * M_PI / 180.0, c = std::cos(phi),
                 s = std::sin(phi);
    const Vec d = 0.5 * (p0 - p1);
    const Vec q(c * d.x() + s * d.y(), -s * d.x() + c * d.y());                   // eq. F.6.5.1
    const double lambda = q.x() * q.x() / (rx * rx) + q.y() * q.y() / (ry * ry);  // F.6.6.2
    if (lambda > 1) {
      rx *= std::sqrt(lambda);
      ry *= std::sqrt(lambda);
    }
    const double num = rx * rx * ry * ry - rx * rx * q.y() * q.y() - ry * ry * q.x() * q.x();
    const double den = rx * rx * q.y() * q.y() + ry * ry * q.x() * q.x();
    double k = den > 0 ? std::sqrt(std::max(0.0, num / den)) : 0.0;  // eq. F.6.5.2
    if (large == sweep) k = -k;
    const Vec cq(k * rx * q.y() / ry, -k * ry * q.x() / rx);
    const Vec mid = 0.5 * (p0 + p1);
    const Vec center(c * cq.x() - s * cq.y() + mid.x(),
                     s * cq.x() + c * cq.y() + mid.y());  // F.6.5.3
    const auto angle = [](const Vec& u, const Vec& v) {
      return std::atan2(u.x() * v.y() - u.y() * v.x(), u.dot(v));
    };
    const Vec u1((q.x() - cq.x()) / rx, (q.y() - cq.y()) / ry);
    const Vec u2((-q.x() - cq.x()) / rx, (-q.y() - cq.y()) / ry);
    const double theta1 = angle({1, 0}, u1);  // F.6.5.5
    double dtheta = angle(u1, u2);            // F.6.5.6
    if (!sweep && dtheta > 0) dtheta -= 2 * M_PI;
    if (sweep && dtheta < 0) dtheta += 2 * M_PI;
    if (!std::isfinite(center.x()) || !std::isfinite(center.y()) || !std::isfinite(dtheta)) {
      Line(p1);
      return;
    }
    const int n = Segments(std::max(rx, ry), dtheta);
    for (int i = 1; i <= n; ++i) {
      const double a = theta1 + dtheta * i / n;
      const double x = rx * std::cos(a), y = ry * std::sin(a);
      Line(i == n ? p1 : Vec(c * x - s * y + center.x(), s * x + c * y + center.y()));
    }
  }

  Status Path(const std::string& d, const std::string& where) {
    NumberReader r(d);
    Vec pen = Vec::Zero(), start = pen, last_ctrl = pen;
    char cmd = 0, prev = 0;
    const auto fail = [&](const std::string& what) {
      return ParseError(where + ": d, at " + std::to_string(r.position()) + ": " + what);
    };
    while (!r.Done()) {
      if (points_ > kMaxPoints) break;
      if (IsAlpha(r.Peek())) {
        cmd = r.Peek();
        r.Advance();
      } else if (cmd == 0) {
        return fail("path data must start with a command");
      }
      const bool rel = std::islower(static_cast<unsigned char>(cmd));
      const char up = static_cast<char>(std::toupper(static_cast<unsigned char>(cmd)));
      const Vec base = rel ? pen : Vec::Zero();
      double v[7];
      const auto read = [&](int n) {
        for (int k = 0; k < n; ++k) {
          if (!r.Number(&v[k])) return false;
        }
        return true;
      };
      switch (up) {
        case 'Z':
          End(true);
          pen = start;
          prev = 'Z';
          cmd = 0;
          continue;
        case 'M':
          if (!read(2)) return fail("M needs x y");
          pen = base + Vec(v[0], v[1]);
          start = pen;
          Begin(pen);
          cmd = rel ? 'l' : 'L';  // further pairs are lines
          break;
        case 'L':
          if (!read(2)) return fail("L needs x y");
          pen = base + Vec(v[0], v[1]);
          if (current_.points.empty()) Begin(start);
          Line(pen);
          break;
        case 'H':
          if (!read(1)) return fail("H needs x");
          pen.x() = (rel ? pen.x() : 0.0) + v[0];
          if (current_.points.empty()) Begin(start);
          Line(pen);
          break;
        case 'V':
          if (!read(1)) return fail("V needs y");
          pen.y() = (rel ? pen.y() : 0.0) + v[0];
          if (current_.points.empty()) Begin(start);
          Line(pen);
          break;
        case 'C':
        case 'S':
        case 'Q':
        case 'T': {
          Vec c1, c2, end;
          if (up == 'C') {
            if (!read(6)) return fail("C needs 6 numbers");
            c1 = base + Vec(v[0], v[1]);
            c2 = base + Vec(v[2], v[3]);
            end = base + Vec(v[4], v[5]);
          } else if (up == 'S') {
            if (!read(4)) return fail("S needs 4 numbers");
            c1 = (prev == 'C' || prev == 'S') ? Vec(2 * pen - last_ctrl) : pen;
            c2 = base + Vec(v[0], v[1]);
            end = base + Vec(v[2], v[3]);
          } else {
            Vec q;
            if (up == 'Q') {
              if (!read(4)) return fail("Q needs 4 numbers");
              q = base + Vec(v[0], v[1]);
              end = base + Vec(v[2], v[3]);
            } else {
              if (!read(2)) return fail("T needs 2 numbers");
              q = (prev == 'Q' || prev == 'T') ? Vec(2 * pen - last_ctrl) : pen;
              end = base + Vec(v[0], v[1]);
            }
            c1 = pen + 2.0 / 3.0 * (q - pen);  // the quadratic as a cubic
            c2 = end + 2.0 / 3.0 * (q - end);
            last_ctrl = q;
          }
          if (current_.points.empty()) Begin(pen);
          Cubic(pen, c1, c2, end);
          if (up == 'C' || up == 'S') last_ctrl = c2;
          pen = end;
          break;
        }
        case 'A': {
          double large = 0, sweep = 0;
          if (!r.Number(&v[0]) || !r.Number(&v[1]) || !r.Number(&v[2]) || !r.Flag(&large) ||
              !r.Flag(&sweep) || !r.Number(&v[3]) || !r.Number(&v[4])) {
            return fail("A needs rx ry rotation large-arc-flag sweep-flag x y");
          }
          const Vec end = base + Vec(v[3], v[4]);
          if (current_.points.empty()) Begin(pen);
          Arc(pen, v[0], v[1], v[2], large != 0, sweep != 0, end);
          pen = end;
          break;
        }
        default:
          return fail(std::string("unknown path command '") + cmd + "'");
      }
      prev = up;
    }
    End(false);
    return Status::Ok();
  }

  std::string origin_;
  double tol_;
  std::unordered_map<std::string, const XMLElement*> ids_;
  StyleSheet sheet_;
  Status css_status_;
  std::unordered_map<const XMLElement*, Properties> declared_;
  std::map<std::string, bool> font_found_;    // fontconfig pattern -> the family is installed
  std::vector<const XMLElement*> use_stack_;  // targets of the <use> elements being drawn
  std::vector<Vec> viewports_;                // sizes in user units, for percentages
  std::map<std::string, int> warning_counts_;
  std::vector<std::string> warning_order_;
  int dropped_warnings_ = 0;
  long elements_ = 0;
  size_t points_ = 0;
  bool bad_coordinates_ = false;
  Affine tf_ = Affine::Identity();
  Affine units_ = Affine::Identity();
  bool fill_none_ = false;
  Polyline current_;
  VectorPattern out_;
};

}  // namespace

Result<VectorPattern> ParseSvg(const std::string& text, const std::string& origin,
                               double tolerance_mm) {
  if (!(tolerance_mm > 0)) return InvalidArgument("SVG flattening tolerance must be > 0");
  if (text.size() > kMaxFileBytes) {
    return InvalidArgument(origin + ": larger than " + std::to_string(kMaxFileBytes >> 20) +
                           " MB, not read");
  }
  tinyxml2::XMLDocument doc;
  if (doc.Parse(text.c_str(), text.size()) != tinyxml2::XML_SUCCESS) {
    return ParseError(origin + ": not well-formed XML (line " + std::to_string(doc.ErrorLineNum()) +
                      "): " + doc.ErrorStr());
  }
  const XMLElement* root = doc.RootElement();
  if (root == nullptr || LocalName(root) != "svg") {
    return ParseError(origin + ": the root element is not <svg>");
  }
  // The root viewport in mm from width and height; its viewBox onto it; y flipped (SVG y runs
  // down, pattern y up). Without a viewBox, 1 user unit is 1 px; a missing width or height
  // follows the viewBox's aspect.
  double w_mm = 0, h_mm = 0, w_unit_mm = 0, h_unit_mm = 0;
  std::string w_unit, h_unit;
  const bool has_w = LengthMm(root->Attribute("width"), &w_mm, &w_unit, &w_unit_mm);
  const bool has_h = LengthMm(root->Attribute("height"), &h_mm, &h_unit, &h_unit_mm);
  const double px_mm = 1.0 / kPxPerMm;
  Affine user_to_mm = Affine::Identity();
  Vec viewport = Vec::Zero();
  std::string units = has_w ? w_unit : has_h ? h_unit : "px (1/96 in)";
  const double unit_mm = has_w ? w_unit_mm : has_h ? h_unit_mm : px_mm;
  if (const char* vb = root->Attribute("viewBox")) {
    double v[4];
    if (!ParseViewBox(vb, v)) {
      return ParseError(origin + ": <svg> viewBox must be four numbers, width and height > 0");
    }
    if (!has_w && !has_h) {
      w_mm = v[2] * px_mm;
      h_mm = v[3] * px_mm;
    } else if (!has_h) {
      h_mm = w_mm * v[3] / v[2];
    } else if (!has_w) {
      w_mm = h_mm * v[2] / v[3];
    }
    user_to_mm = ViewBoxTransform(v, w_mm, h_mm, root->Attribute("preserveAspectRatio"));
    viewport = Vec(v[2], v[3]);
    // "mm" when the viewBox counts in the width's unit, else what a user unit is.
    const double mm_per_unit = user_to_mm.linear()(0, 0);
    if (std::abs(mm_per_unit - unit_mm) > 1e-9 * unit_mm) {
      char buf[64];
      std::snprintf(buf, sizeof buf, " (1 user unit = %.6g mm)", mm_per_unit);
      units += buf;
    }
  } else {
    user_to_mm.scale(px_mm);
    viewport = Vec(w_mm, h_mm) / px_mm;
  }
  Affine units_tf = Affine::Identity();
  units_tf.matrix() << 1, 0, 0, 0, -1, 0, 0, 0, 1;
  units_tf = units_tf * user_to_mm;
  if (!units_tf.matrix().allFinite()) return ParseError(origin + ": <svg> size out of range");
  SvgReader reader(origin, tolerance_mm, doc);
  INSITU_RETURN_IF_ERROR(reader.Root(root, units_tf, viewport));
  VectorPattern out = reader.Finish();
  out.units = units;
  if (StartsWith(units, "px")) {
    // Illustrator counts 72 user units per inch where CSS counts 96: its files without a size
    // in absolute units come out at 3/4 of the size the designer saw.
    out.warnings.insert(out.warnings.begin(),
                        "the SVG gives its size in px or not at all: 1 user unit is taken as "
                        "1/96 in (CSS); a file from Illustrator counts 1/72 in and comes out "
                        "at 75 %");
  }
  if (out.paths.empty()) {
    std::string skipped;
    for (const auto& [kind, n] : out.skipped) {
      skipped += (skipped.empty() ? " (not drawn: " : ", ") + std::to_string(n) + " " + kind;
    }
    if (!skipped.empty()) skipped += ")";
    return InvalidArgument(origin + ": the SVG draws nothing insitu can mark" + skipped);
  }
  return out;
}

Result<VectorPattern> LoadSvg(const std::string& path, double tolerance_mm) {
  INSITU_ASSIGN_OR_RETURN(const std::string text, ReadPatternFile(path, "SVG"));
  return ParseSvg(text, path, tolerance_mm);
}

}  // namespace insitu::pattern
