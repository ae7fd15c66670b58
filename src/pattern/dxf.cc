// DXF input (ASCII): the ENTITIES section's LINE, LWPOLYLINE (with bulges), POLYLINE/VERTEX,
// ARC, CIRCLE, ELLIPSE and SPLINE (B-spline by control points and knots, de Boor). Units from
// the header's $INSUNITS (mm when absent). Blocks and INSERTs are not expanded.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "insitu/pattern/vector.h"
#include "pattern/flatten.h"

namespace insitu::pattern {
namespace {

struct Group {
  int code = 0;
  std::string value;
  int line = 0;  // of the code
};

std::string Trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r\n");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r\n") - a + 1);
}

void AppendArc(const Eigen::Vector2d& c, double r, double a0, double a1, double tol,
               std::vector<Eigen::Vector2d>* out, bool include_first) {
  const int n = ArcChords(r, a1 - a0, tol, 2);
  for (int k = include_first ? 0 : 1; k <= n; ++k) {
    const double a = a0 + (a1 - a0) * k / n;
    out->push_back(c + r * Eigen::Vector2d(std::cos(a), std::sin(a)));
  }
}

// Bulge b between p and q: arc with included angle 4 atan(b), counterclockwise for b > 0.
void AppendBulge(const Eigen::Vector2d& p, const Eigen::Vector2d& q, double b, double tol,
                 std::vector<Eigen::Vector2d>* out) {
  if (std::abs(b) < 1e-12) {
    out->push_back(q);
    return;
  }
  const double theta = 4.0 * std::atan(b);
  const double chord = (q - p).norm();
  const double r = chord / (2.0 * std::sin(std::abs(theta) / 2.0));
  const Eigen::Vector2d mid = 0.5 * (p + q);
  const Eigen::Vector2d dir = (q - p) / chord;
  const Eigen::Vector2d left(-dir.y(), dir.x());
  // Centre on the left of p->q for a counterclockwise arc under 180 degrees.
  const double h = r * std::cos(theta / 2.0);
  const Eigen::Vector2d c = mid + (b > 0 ? 1.0 : -1.0) * h * left;
  const double a0 = std::atan2(p.y() - c.y(), p.x() - c.x());
  AppendArc(c, r, a0, a0 + theta, tol, out, false);
}

double InsUnitsToMm(int code) {
  switch (code) {
    case 1: return 25.4;     // inches
    case 2: return 304.8;    // feet
    case 4: return 1.0;      // mm
    case 5: return 10.0;     // cm
    case 6: return 1000.0;   // m
    case 8: return 25.4e-6;  // microinches
    case 9: return 25.4e-3;  // mils
    case 13: return 1e-3;    // microns
    default: return 1.0;     // unitless / unknown: mm
  }
}

class DxfReader {
 public:
  DxfReader(std::string origin, double tol) : origin_(std::move(origin)), tol_(tol) {}

  Status Read(const std::string& text) {
    std::istringstream in(text);
    std::string code_line, value;
    int line = 0;
    while (std::getline(in, code_line)) {
      ++line;
      const std::string c = Trim(code_line);
      if (c.empty() && in.eof()) break;
      if (!std::getline(in, value)) {
        return ParseError(origin_ + ": line " + std::to_string(line) + ": a group code without its value");
      }
      char* end = nullptr;
      const long code = std::strtol(c.c_str(), &end, 10);
      if (c.empty() || *end != '\0') {
        return ParseError(origin_ + ": line " + std::to_string(line) + ": '" + c +
                          "' is not a DXF group code");
      }
      groups_.push_back({static_cast<int>(code), Trim(value), line});
      ++line;
    }
    if (groups_.empty()) return ParseError(origin_ + ": empty file");
    // Header: $INSUNITS.
    for (size_t i = 0; i + 1 < groups_.size(); ++i) {
      if (groups_[i].code == 9 && groups_[i].value == "$INSUNITS" && groups_[i + 1].code == 70) {
        scale_ = InsUnitsToMm(std::atoi(groups_[i + 1].value.c_str()));
      }
    }
    // Entities.
    size_t i = 0;
    for (; i + 1 < groups_.size(); ++i) {
      if (groups_[i].code == 2 && groups_[i].value == "ENTITIES") break;
    }
    if (i + 1 >= groups_.size()) return ParseError(origin_ + ": no ENTITIES section");
    ++i;
    while (i < groups_.size()) {
      if (groups_[i].code != 0) {
        ++i;
        continue;
      }
      const std::string type = groups_[i].value;
      if (type == "ENDSEC" || type == "EOF") break;
      size_t j = i + 1;
      while (j < groups_.size() && groups_[j].code != 0) ++j;
      if (type == "POLYLINE") {
        INSITU_RETURN_IF_ERROR(OldPolyline(&j, i));
      } else {
        INSITU_RETURN_IF_ERROR(Entity(type, i, j));
      }
      i = j;
    }
    return Status::Ok();
  }

  VectorPattern& pattern() { return out_; }

 private:
  double Value(size_t a, size_t b, int code, double fallback, bool* found = nullptr) const {
    for (size_t k = a; k < b; ++k) {
      if (groups_[k].code == code) {
        if (found) *found = true;
        return std::atof(groups_[k].value.c_str());
      }
    }
    if (found) *found = false;
    return fallback;
  }
  Status Need(size_t a, size_t b, std::initializer_list<int> codes, const std::string& type) const {
    for (int code : codes) {
      bool found = false;
      Value(a, b, code, 0.0, &found);
      if (!found) {
        return ParseError(origin_ + ": line " + std::to_string(groups_[a].line) + ": " + type +
                          " without group " + std::to_string(code));
      }
    }
    for (size_t k = a + 1; k < b; ++k) {
      const int c = groups_[k].code;
      if ((c >= 10 && c <= 59) || (c >= 40 && c <= 42)) {
        char* end = nullptr;
        std::strtod(groups_[k].value.c_str(), &end);
        if (end == groups_[k].value.c_str() || *end != '\0') {
          return ParseError(origin_ + ": line " + std::to_string(groups_[k].line + 1) + ": " + type +
                            " group " + std::to_string(c) + ": '" + groups_[k].value +
                            "' is not a number");
        }
      }
    }
    return Status::Ok();
  }
  Eigen::Vector2d Mm(double x, double y) const { return scale_ * Eigen::Vector2d(x, y); }
  void Add(std::vector<Eigen::Vector2d> pts, bool closed) {
    if (pts.size() < 2) return;
    Polyline p;
    p.points = std::move(pts);
    p.closed = closed && p.points.size() >= 3;
    out_.paths.push_back(std::move(p));
  }

  Status Entity(const std::string& type, size_t a, size_t b) {
    if (type == "LINE") {
      INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20, 11, 21}, type));
      Add({Mm(Value(a, b, 10, 0), Value(a, b, 20, 0)), Mm(Value(a, b, 11, 0), Value(a, b, 21, 0))}, false);
    } else if (type == "CIRCLE" || type == "ARC") {
      INSITU_RETURN_IF_ERROR(Need(a, b, type == "ARC" ? std::initializer_list<int>{10, 20, 40, 50, 51}
                                                      : std::initializer_list<int>{10, 20, 40}, type));
      const Eigen::Vector2d c = Mm(Value(a, b, 10, 0), Value(a, b, 20, 0));
      const double r = scale_ * Value(a, b, 40, 0);
      if (!(r > 0)) return ParseError(origin_ + ": line " + std::to_string(groups_[a].line) + ": " + type + " radius must be > 0");
      std::vector<Eigen::Vector2d> pts;
      if (type == "CIRCLE") {
        AppendArc(c, r, 0.0, 2 * M_PI, tol_, &pts, true);
        pts.pop_back();
        Add(std::move(pts), true);
      } else {
        double a0 = Value(a, b, 50, 0) * M_PI / 180.0, a1 = Value(a, b, 51, 0) * M_PI / 180.0;
        if (a1 <= a0) a1 += 2 * M_PI;  // arcs run counterclockwise
        AppendArc(c, r, a0, a1, tol_, &pts, true);
        Add(std::move(pts), false);
      }
    } else if (type == "ELLIPSE") {
      INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20, 11, 21, 40}, type));
      const Eigen::Vector2d c = Mm(Value(a, b, 10, 0), Value(a, b, 20, 0));
      const Eigen::Vector2d major = Mm(Value(a, b, 11, 0), Value(a, b, 21, 0));
      const Eigen::Vector2d minor = Value(a, b, 40, 1) * Eigen::Vector2d(-major.y(), major.x());
      double t0 = Value(a, b, 41, 0), t1 = Value(a, b, 42, 2 * M_PI);
      if (t1 <= t0) t1 += 2 * M_PI;
      const bool full = std::abs(t1 - t0 - 2 * M_PI) < 1e-9;
      const int n = ArcChords(major.norm(), t1 - t0, tol_, 2);
      std::vector<Eigen::Vector2d> pts;
      for (int k = 0; k < (full ? n : n + 1); ++k) {
        const double t = t0 + (t1 - t0) * k / n;
        pts.push_back(c + std::cos(t) * major + std::sin(t) * minor);
      }
      Add(std::move(pts), full);
    } else if (type == "LWPOLYLINE") {
      INSITU_RETURN_IF_ERROR(Need(a, b, {10, 20}, type));
      std::vector<Eigen::Vector2d> v;
      std::vector<double> bulge;
      for (size_t k = a + 1; k < b; ++k) {
        if (groups_[k].code == 10) {
          v.push_back(Mm(std::atof(groups_[k].value.c_str()), 0));
          bulge.push_back(0.0);
        } else if (groups_[k].code == 20 && !v.empty()) {
          v.back().y() = scale_ * std::atof(groups_[k].value.c_str());
        } else if (groups_[k].code == 42 && !v.empty()) {
          bulge.back() = std::atof(groups_[k].value.c_str());
        }
      }
      const bool closed = (static_cast<int>(Value(a, b, 70, 0)) & 1) != 0;
      Add(Bulged(v, bulge, closed), closed);
    } else if (type == "SPLINE") {
      INSITU_RETURN_IF_ERROR(Need(a, b, {71, 10, 20}, type));
      const int degree = static_cast<int>(Value(a, b, 71, 3));
      std::vector<double> knots;
      std::vector<Eigen::Vector2d> ctrl;
      for (size_t k = a + 1; k < b; ++k) {
        if (groups_[k].code == 40) knots.push_back(std::atof(groups_[k].value.c_str()));
        if (groups_[k].code == 10) ctrl.push_back(Mm(std::atof(groups_[k].value.c_str()), 0));
        if (groups_[k].code == 20 && !ctrl.empty()) ctrl.back().y() = scale_ * std::atof(groups_[k].value.c_str());
      }
      if (degree < 1 || ctrl.size() < static_cast<size_t>(degree) + 1 ||
          knots.size() != ctrl.size() + degree + 1) {
        return ParseError(origin_ + ": line " + std::to_string(groups_[a].line) +
                          ": SPLINE needs degree + 1 control points and #control + degree + 1 knots (fit-point splines are not read)");
      }
      Add(Spline(degree, knots, ctrl), (static_cast<int>(Value(a, b, 70, 0)) & 1) != 0);
    } else {
      ++out_.ignored_commands;  // TEXT, HATCH, INSERT, DIMENSION...: no geometry to mark here
    }
    return Status::Ok();
  }

  // POLYLINE followed by VERTEX entities up to SEQEND.
  Status OldPolyline(size_t* j, size_t a) {
    const bool closed = (static_cast<int>(Value(a, *j, 70, 0)) & 1) != 0;
    std::vector<Eigen::Vector2d> v;
    std::vector<double> bulge;
    size_t i = *j;
    while (i < groups_.size() && groups_[i].code == 0 && groups_[i].value == "VERTEX") {
      size_t e = i + 1;
      while (e < groups_.size() && groups_[e].code != 0) ++e;
      v.push_back(Mm(Value(i, e, 10, 0), Value(i, e, 20, 0)));
      bulge.push_back(Value(i, e, 42, 0));
      i = e;
    }
    if (i < groups_.size() && groups_[i].value == "SEQEND") {
      ++i;
      while (i < groups_.size() && groups_[i].code != 0) ++i;
    }
    *j = i;
    Add(Bulged(v, bulge, closed), closed);
    return Status::Ok();
  }

  std::vector<Eigen::Vector2d> Bulged(const std::vector<Eigen::Vector2d>& v,
                                      const std::vector<double>& bulge, bool closed) const {
    std::vector<Eigen::Vector2d> pts;
    if (v.empty()) return pts;
    pts.push_back(v[0]);
    const size_t n = v.size();
    for (size_t k = 0; k + (closed ? 0 : 1) < n; ++k) {
      AppendBulge(v[k], v[(k + 1) % n], bulge[k], tol_, &pts);
    }
    if (closed && pts.size() > 1) pts.pop_back();  // back at the start
    return pts;
  }

  std::vector<Eigen::Vector2d> Spline(int p, const std::vector<double>& u,
                                      const std::vector<Eigen::Vector2d>& ctrl) const {
    // de Boor at evenly spaced parameters. A chord c on a curve of radius R departs from it by
    // c^2 / (8 R): chords of sqrt(8 R tol) stay within the tolerance; R >= 1 mm is assumed
    // (tighter bends in a marking pattern are below the spot size anyway). The control
    // polygon's length bounds the curve's.
    constexpr double kMinRadiusMm = 1.0;
    double length = 0;
    for (size_t k = 1; k < ctrl.size(); ++k) length += (ctrl[k] - ctrl[k - 1]).norm();
    const int n = std::clamp(static_cast<int>(length / std::sqrt(8.0 * kMinRadiusMm * tol_)), 16, 20000);
    const double u0 = u[p], u1 = u[u.size() - p - 1];
    std::vector<Eigen::Vector2d> out;
    for (int s = 0; s <= n; ++s) {
      const double t = std::min(u0 + (u1 - u0) * s / n, u1 - 1e-12 * (u1 - u0));
      size_t k = p;
      while (k + 1 < u.size() - p - 1 && u[k + 1] <= t) ++k;
      std::vector<Eigen::Vector2d> d(ctrl.begin() + (k - p), ctrl.begin() + (k + 1));
      for (int r = 1; r <= p; ++r) {
        for (int j = p; j >= r; --j) {
          const size_t i = k - p + j;
          const double denom = u[i + p - r + 1] - u[i];
          const double alpha = denom > 0 ? (t - u[i]) / denom : 0.0;
          d[j] = (1 - alpha) * d[j - 1] + alpha * d[j];
        }
      }
      out.push_back(d[p]);
    }
    return out;
  }

  std::string origin_;
  double tol_;
  double scale_ = 1.0;
  std::vector<Group> groups_;
  VectorPattern out_;
};

}  // namespace

Result<VectorPattern> ParseDxf(const std::string& text, const std::string& origin,
                               double tolerance_mm) {
  if (!(tolerance_mm > 0)) return InvalidArgument("DXF flattening tolerance must be > 0");
  DxfReader reader(origin, tolerance_mm);
  INSITU_RETURN_IF_ERROR(reader.Read(text));
  VectorPattern out = std::move(reader.pattern());
  if (out.paths.empty()) return InvalidArgument(origin + ": the DXF draws nothing insitu can mark");
  return out;
}

Result<VectorPattern> LoadDxf(const std::string& path, double tolerance_mm) {
  INSITU_ASSIGN_OR_RETURN(const std::string text, ReadPatternFile(path, "DXF"));
  return ParseDxf(text, path, tolerance_mm);
}

}  // namespace insitu::pattern
