// SVG input. tinyxml2 reads the XML; the path grammar, transforms and curve flattening are
// here (no SVG library in Debian fits: librsvg renders to pixels, which would lose the vector).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <tinyxml2.h>

#include "insitu/pattern/vector.h"
#include "pattern/flatten.h"

namespace insitu::pattern {
namespace {

using Affine = Eigen::Affine2d;

// Reads numbers out of SVG attribute text: separators are whitespace and commas, and a sign
// or a second '.' starts a new number ("1-2.5.5" is 1, -2.5, .5); arc flags may be packed.
// The reader owns a copy of its text, so it may be built from a temporary (an attribute value)
// and outlive it.
class NumberReader {
 public:
  explicit NumberReader(std::string s) : s_(std::move(s)) {}
  void SkipSeparators() {
    while (i_ < s_.size() && (std::isspace(static_cast<unsigned char>(s_[i_])) || s_[i_] == ',')) ++i_;
  }
  bool AtNumber() {
    SkipSeparators();
    if (i_ >= s_.size()) return false;
    const char c = s_[i_];
    return std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.';
  }
  bool Number(double* out) {
    if (!AtNumber()) return false;
    const char* begin = s_.c_str() + i_;
    char* end = nullptr;
    *out = std::strtod(begin, &end);
    if (end == begin) return false;
    i_ += static_cast<size_t>(end - begin);
    return std::isfinite(*out);
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
    while (i < text.size() && (std::isspace(static_cast<unsigned char>(text[i])) || text[i] == ',')) ++i;
    if (i >= text.size()) break;
    const size_t open = text.find('(', i), close = text.find(')', i);
    if (open == std::string::npos || close == std::string::npos || close < open) {
      return ParseError(where + ": transform '" + text + "' is malformed");
    }
    std::string name = text.substr(i, open - i);
    name.erase(std::remove_if(name.begin(), name.end(), [](unsigned char c) { return std::isspace(c); }), name.end());
    const std::string args = text.substr(open + 1, close - open - 1);
    NumberReader r(args);
    std::vector<double> v;
    double x;
    while (r.Number(&x)) v.push_back(x);
    if (!r.Done()) return ParseError(where + ": transform " + name + "(" + args + ") has a non-number");
    Affine m = Affine::Identity();
    if (name == "matrix" && v.size() == 6) {
      m.matrix() << v[0], v[2], v[4], v[1], v[3], v[5], 0, 0, 1;
    } else if (name == "translate" && (v.size() == 1 || v.size() == 2)) {
      m.translate(Eigen::Vector2d(v[0], v.size() == 2 ? v[1] : 0.0));
    } else if (name == "scale" && (v.size() == 1 || v.size() == 2)) {
      m.scale(Eigen::Vector2d(v[0], v.size() == 2 ? v[1] : v[0]));
    } else if (name == "rotate" && (v.size() == 1 || v.size() == 3)) {
      const Eigen::Vector2d c = v.size() == 3 ? Eigen::Vector2d(v[1], v[2]) : Eigen::Vector2d::Zero();
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

// Length in mm of an SVG length ("100mm", "4in", "300", "300px").
bool LengthMm(const char* text, double* mm) {
  if (text == nullptr) return false;
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || !std::isfinite(v) || v <= 0) return false;
  std::string unit(end);
  unit.erase(std::remove_if(unit.begin(), unit.end(), [](unsigned char c) { return std::isspace(c); }), unit.end());
  double per = 0;
  if (unit == "mm") per = 1.0;
  else if (unit == "cm") per = 10.0;
  else if (unit == "in") per = 25.4;
  else if (unit == "pt") per = 25.4 / 72.0;
  else if (unit == "pc") per = 25.4 / 6.0;
  else if (unit.empty() || unit == "px") per = 25.4 / 96.0;
  else return false;
  *mm = v * per;
  return true;
}

class SvgReader {
 public:
  SvgReader(std::string origin, double tolerance_mm) : origin_(std::move(origin)), tol_(tolerance_mm) {}

  Status Element(const tinyxml2::XMLElement* e, const Affine& parent, bool parent_fill_none) {
    Affine t = parent;
    const std::string name = e->Name();
    const std::string where = origin_ + ": <" + name + (e->Attribute("id") ? std::string(" id=\"") + e->Attribute("id") + "\"" : "") +
                              "> (line " + std::to_string(e->GetLineNum()) + ")";
    if (const char* tr = e->Attribute("transform")) {
      INSITU_ASSIGN_OR_RETURN(Affine m, ParseTransform(tr, where));
      t = t * m;
    }
    bool fill_none = parent_fill_none;
    if (const char* f = e->Attribute("fill")) fill_none = std::string(f) == "none";
    if (const char* style = e->Attribute("style")) {
      const std::string s(style);
      if (s.find("fill:none") != std::string::npos) fill_none = true;
    }
    tf_ = t;
    fill_none_ = fill_none;
    if (name == "g" || name == "svg" || name == "a") {
      for (auto* c = e->FirstChildElement(); c != nullptr; c = c->NextSiblingElement()) {
        INSITU_RETURN_IF_ERROR(Element(c, t, fill_none));
      }
      return Status::Ok();
    }
    if (name == "path") return Path(Attr(e, "d"), where);
    if (name == "line") {
      Begin(Eigen::Vector2d(Num(e, "x1"), Num(e, "y1")));
      Line(Eigen::Vector2d(Num(e, "x2"), Num(e, "y2")));
      End(false);
      return Status::Ok();
    }
    if (name == "polyline" || name == "polygon") {
      NumberReader r(Attr(e, "points"));
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
      const double x = Num(e, "x"), y = Num(e, "y"), w = Num(e, "width"), h = Num(e, "height");
      if (!(w > 0 && h > 0)) return ParseError(where + ": width and height must be > 0");
      Begin({x, y});
      Line({x + w, y});
      Line({x + w, y + h});
      Line({x, y + h});
      End(true);
      return Status::Ok();
    }
    if (name == "circle" || name == "ellipse") {
      const double cx = Num(e, "cx"), cy = Num(e, "cy");
      const double rx = name == "circle" ? Num(e, "r") : Num(e, "rx");
      const double ry = name == "circle" ? rx : Num(e, "ry");
      if (!(rx > 0 && ry > 0)) return ParseError(where + ": radius must be > 0");
      const int n = Segments(std::max(rx, ry), 2 * M_PI);
      Begin({cx + rx, cy});
      for (int k = 1; k < n; ++k) {
        const double a = 2 * M_PI * k / n;
        Line({cx + rx * std::cos(a), cy + ry * std::sin(a)});
      }
      End(true);
      return Status::Ok();
    }
    return Status::Ok();  // text, images, defs, metadata...: nothing to mark
  }

  VectorPattern& pattern() { return out_; }
  void set_units(const Affine& units) { units_ = units; }

 private:
  static std::string Attr(const tinyxml2::XMLElement* e, const char* name) {
    const char* v = e->Attribute(name);
    return v ? v : "";
  }
  static double Num(const tinyxml2::XMLElement* e, const char* name) {
    return e->DoubleAttribute(name, 0.0);
  }
  // Chords of a circle of radius r (user units) within the tolerance: sagitta r (1 - cos(a/2)).
  int Segments(double r_user, double angle) const {
    const double scale = std::sqrt(std::abs((units_ * tf_).linear().determinant()));
    return ArcChords(r_user * scale, angle, tol_, 4);
  }
  void Begin(const Eigen::Vector2d& p) {
    End(false);
    current_.points.push_back(units_ * tf_ * p);
  }
  void Line(const Eigen::Vector2d& p) { current_.points.push_back(units_ * tf_ * p); }
  void End(bool closed) {
    if (current_.points.size() >= 2) {
      if (closed && (current_.points.front() - current_.points.back()).norm() < 1e-9) {
        current_.points.pop_back();
      }
      if (closed && fill_none_) {
        // fill="none": an outline to follow, not an area to hatch.
        current_.points.push_back(current_.points.front());
      } else {
        current_.closed = closed && current_.points.size() >= 3;
      }
      out_.paths.push_back(current_);
    }
    current_ = Polyline{};
  }
  void Cubic(const Eigen::Vector2d& p0, const Eigen::Vector2d& p1, const Eigen::Vector2d& p2,
             const Eigen::Vector2d& p3) {
    const double length = (p1 - p0).norm() + (p2 - p1).norm() + (p3 - p2).norm();
    const double scale = std::sqrt(std::abs((units_ * tf_).linear().determinant()));
    // Flatness of a cubic: max deviation <= 3/4 max(|second differences|) / n^2.
    const double dd = std::max((p0 - 2 * p1 + p2).norm(), (p1 - 2 * p2 + p3).norm()) * scale;
    const int n = std::clamp(static_cast<int>(std::ceil(std::sqrt(0.75 * dd / tol_))), 1,
                             std::max(1, static_cast<int>(length * scale / 0.001)));
    for (int k = 1; k <= n; ++k) {
      const double t = static_cast<double>(k) / n, u = 1 - t;
      Line(u * u * u * p0 + 3 * u * u * t * p1 + 3 * u * t * t * p2 + t * t * t * p3);
    }
  }
  // SVG arc (endpoint parameterisation, implementation notes F.6.5).
  void Arc(const Eigen::Vector2d& p0, double rx, double ry, double phi_deg, bool large, bool sweep,
           const Eigen::Vector2d& p1) {
    if ((p1 - p0).norm() < 1e-12) return;
    rx = std::abs(rx);
    ry = std::abs(ry);
    if (rx < 1e-12 || ry < 1e-12) {
      Line(p1);
      return;
    }
    const double phi = phi_deg * M_PI / 180.0, c = std::cos(phi), s = std::sin(phi);
    const Eigen::Vector2d d = 0.5 * (p0 - p1);
    const Eigen::Vector2d q(c * d.x() + s * d.y(), -s * d.x() + c * d.y());
    const double lambda = q.x() * q.x() / (rx * rx) + q.y() * q.y() / (ry * ry);
    if (lambda > 1) {
      rx *= std::sqrt(lambda);
      ry *= std::sqrt(lambda);
    }
    const double num = rx * rx * ry * ry - rx * rx * q.y() * q.y() - ry * ry * q.x() * q.x();
    const double den = rx * rx * q.y() * q.y() + ry * ry * q.x() * q.x();
    double k = std::sqrt(std::max(0.0, num / den));
    if (large == sweep) k = -k;
    const Eigen::Vector2d cq(k * rx * q.y() / ry, -k * ry * q.x() / rx);
    const Eigen::Vector2d mid = 0.5 * (p0 + p1);
    const Eigen::Vector2d center(c * cq.x() - s * cq.y() + mid.x(), s * cq.x() + c * cq.y() + mid.y());
    auto angle = [](const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
      return std::atan2(u.x() * v.y() - u.y() * v.x(), u.dot(v));
    };
    const Eigen::Vector2d u1((q.x() - cq.x()) / rx, (q.y() - cq.y()) / ry);
    const Eigen::Vector2d u2((-q.x() - cq.x()) / rx, (-q.y() - cq.y()) / ry);
    const double theta1 = angle({1, 0}, u1);
    double dtheta = angle(u1, u2);
    if (!sweep && dtheta > 0) dtheta -= 2 * M_PI;
    if (sweep && dtheta < 0) dtheta += 2 * M_PI;
    const int n = Segments(std::max(rx, ry), dtheta);
    for (int i = 1; i <= n; ++i) {
      const double a = theta1 + dtheta * i / n;
      const double x = rx * std::cos(a), y = ry * std::sin(a);
      Line(i == n ? p1 : Eigen::Vector2d(c * x - s * y + center.x(), s * x + c * y + center.y()));
    }
  }

  Status Path(const std::string& d, const std::string& where) {
    NumberReader r(d);
    Eigen::Vector2d pen = Eigen::Vector2d::Zero(), start = pen, last_ctrl = pen;
    char cmd = 0, prev = 0;
    auto fail = [&](const std::string& what) {
      return ParseError(where + ": d, at " + std::to_string(r.position()) + ": " + what);
    };
    while (!r.Done()) {
      if (std::isalpha(static_cast<unsigned char>(r.Peek()))) {
        cmd = r.Peek();
        r.Advance();
      } else if (cmd == 0) {
        return fail("path data must start with a command");
      }
      const bool rel = std::islower(static_cast<unsigned char>(cmd));
      const char up = static_cast<char>(std::toupper(static_cast<unsigned char>(cmd)));
      const Eigen::Vector2d base = rel ? pen : Eigen::Vector2d::Zero();
      double v[7];
      auto read = [&](int n) {
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
          pen = base + Eigen::Vector2d(v[0], v[1]);
          start = pen;
          Begin(pen);
          cmd = rel ? 'l' : 'L';  // further pairs are lines
          break;
        case 'L':
          if (!read(2)) return fail("L needs x y");
          pen = base + Eigen::Vector2d(v[0], v[1]);
          Line(pen);
          break;
        case 'H':
          if (!read(1)) return fail("H needs x");
          pen.x() = (rel ? pen.x() : 0.0) + v[0];
          Line(pen);
          break;
        case 'V':
          if (!read(1)) return fail("V needs y");
          pen.y() = (rel ? pen.y() : 0.0) + v[0];
          Line(pen);
          break;
        case 'C': case 'S': case 'Q': case 'T': {
          Eigen::Vector2d c1, c2, end;
          if (up == 'C') {
            if (!read(6)) return fail("C needs 6 numbers");
            c1 = base + Eigen::Vector2d(v[0], v[1]);
            c2 = base + Eigen::Vector2d(v[2], v[3]);
            end = base + Eigen::Vector2d(v[4], v[5]);
          } else if (up == 'S') {
            if (!read(4)) return fail("S needs 4 numbers");
            c1 = (prev == 'C' || prev == 'S') ? Eigen::Vector2d(2 * pen - last_ctrl) : pen;
            c2 = base + Eigen::Vector2d(v[0], v[1]);
            end = base + Eigen::Vector2d(v[2], v[3]);
          } else {
            Eigen::Vector2d q;
            if (up == 'Q') {
              if (!read(4)) return fail("Q needs 4 numbers");
              q = base + Eigen::Vector2d(v[0], v[1]);
              end = base + Eigen::Vector2d(v[2], v[3]);
            } else {
              if (!read(2)) return fail("T needs 2 numbers");
              q = (prev == 'Q' || prev == 'T') ? Eigen::Vector2d(2 * pen - last_ctrl) : pen;
              end = base + Eigen::Vector2d(v[0], v[1]);
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
          const Eigen::Vector2d end = base + Eigen::Vector2d(v[3], v[4]);
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
  tinyxml2::XMLDocument doc;
  if (doc.Parse(text.c_str(), text.size()) != tinyxml2::XML_SUCCESS) {
    return ParseError(origin + ": not well-formed XML (line " + std::to_string(doc.ErrorLineNum()) +
                      "): " + doc.ErrorStr());
  }
  const tinyxml2::XMLElement* root = doc.RootElement();
  if (root == nullptr || std::string(root->Name()) != "svg") {
    return ParseError(origin + ": the root element is not <svg>");
  }
  // User units to mm, y flipped (SVG y runs down; pattern y up).
  double sx = 25.4 / 96.0, sy = sx, ox = 0, oy = 0;
  double w_mm = 0, h_mm = 0;
  const bool has_w = LengthMm(root->Attribute("width"), &w_mm);
  const bool has_h = LengthMm(root->Attribute("height"), &h_mm);
  if (const char* vb = root->Attribute("viewBox")) {
    std::string text_vb(vb);
    NumberReader r(text_vb);
    double v[4];
    for (double& x : v) {
      if (!r.Number(&x)) return ParseError(origin + ": <svg> viewBox must be four numbers");
    }
    if (!(v[2] > 0 && v[3] > 0)) return ParseError(origin + ": <svg> viewBox width and height must be > 0");
    if (has_w) sx = w_mm / v[2];
    if (has_h) sy = h_mm / v[3];
    if (has_w && !has_h) sy = sx;
    if (has_h && !has_w) sx = sy;
    ox = v[0];
    oy = v[1];
  }
  Affine units = Affine::Identity();
  units.matrix() << sx, 0, -sx * ox, 0, -sy, sy * oy, 0, 0, 1;
  SvgReader reader(origin, tolerance_mm);
  reader.set_units(units);
  INSITU_RETURN_IF_ERROR(reader.Element(root, Affine::Identity(), false));
  VectorPattern out = std::move(reader.pattern());
  if (out.paths.empty()) return InvalidArgument(origin + ": the SVG draws nothing insitu can mark");
  return out;
}

Result<VectorPattern> LoadSvg(const std::string& path, double tolerance_mm) {
  INSITU_ASSIGN_OR_RETURN(const std::string text, ReadPatternFile(path, "SVG"));
  return ParseSvg(text, path, tolerance_mm);
}

}  // namespace insitu::pattern
