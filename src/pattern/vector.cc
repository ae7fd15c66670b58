#include "insitu/pattern/vector.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <utility>

#include "pattern/flatten.h"
#include "pattern/hatch_order.h"

namespace insitu::pattern {

void VectorPattern::Append(VectorPattern other) {
  for (Polyline& p : other.paths) paths.push_back(std::move(p));
  ignored_commands += other.ignored_commands;
  for (const auto& [kind, n] : other.skipped) skipped[kind] += n;
  for (const auto& [kind, n] : other.converted) converted[kind] += n;
  texts += other.texts;
  for (std::string& w : other.warnings) warnings.push_back(std::move(w));
}

namespace {

constexpr double kHpglUnitsPerMm = 40.0;

}  // namespace

Result<VectorPattern> ParseHpgl(const std::string& text, const std::string& origin) {
  VectorPattern out;
  Eigen::Vector2d pen = Eigen::Vector2d::Zero();
  bool down = false, relative = false;
  Polyline current;
  auto flush = [&]() {
    if (current.points.size() >= 2) {
      if ((current.points.front() - current.points.back()).norm() < 1e-9 &&
          current.points.size() >= 4) {
        current.points.pop_back();
        current.closed = true;
      }
      out.paths.push_back(current);
    }
    current = Polyline{};
  };
  size_t i = 0;
  const size_t n = text.size();
  while (i < n) {
    const unsigned char c = text[i];
    if (std::isspace(c) || c == ';' || c == ',') {
      ++i;
      continue;
    }
    if (!std::isalpha(c) || i + 1 >= n || !std::isalpha(static_cast<unsigned char>(text[i + 1]))) {
      return ParseError(origin + ": byte " + std::to_string(i) +
                        ": expected a two-letter "
                        "HPGL command, found '" +
                        text.substr(i, 8) + "'");
    }
    const std::string cmd{static_cast<char>(std::toupper(c)),
                          static_cast<char>(std::toupper(static_cast<unsigned char>(text[i + 1])))};
    const size_t at = i;
    i += 2;
    // Parameters: up to the next letter or ';'.
    size_t end = i;
    while (end < n && text[end] != ';' && !std::isalpha(static_cast<unsigned char>(text[end])))
      ++end;
    const std::string params = text.substr(i, end - i);
    i = end;
    if (cmd != "PU" && cmd != "PD" && cmd != "PA" && cmd != "PR" && cmd != "IN") {
      ++out.ignored_commands;
      continue;
    }
    std::vector<double> values;
    {
      std::string p = params;
      std::replace(p.begin(), p.end(), ',', ' ');
      std::istringstream is(p);
      std::string token;
      while (is >> token) {
        char* stop = nullptr;
        const double v = std::strtod(token.c_str(), &stop);
        if (stop == token.c_str() || *stop != '\0' || !std::isfinite(v)) {
          return ParseError(origin + ": byte " + std::to_string(at) + ": " + cmd + ": '" + token +
                            "' is not a number");
        }
        values.push_back(v);
      }
    }
    if (values.size() % 2 != 0) {
      return ParseError(origin + ": byte " + std::to_string(at) + ": " + cmd + " has " +
                        std::to_string(values.size()) + " coordinates, expected pairs");
    }
    if (cmd == "IN") {
      flush();
      pen.setZero();
      down = relative = false;
      continue;
    }
    if (cmd == "PA") relative = false;
    if (cmd == "PR") relative = true;
    if (cmd == "PU") {
      flush();
      down = false;
    }
    if (cmd == "PD" && !down) {
      down = true;
      current.points.push_back(pen);
    }
    for (size_t k = 0; k < values.size(); k += 2) {
      const Eigen::Vector2d v(values[k] / kHpglUnitsPerMm, values[k + 1] / kHpglUnitsPerMm);
      pen = relative ? Eigen::Vector2d(pen + v) : v;
      if (down) current.points.push_back(pen);
    }
  }
  flush();
  if (out.paths.empty()) return InvalidArgument(origin + ": the plot draws nothing (no PD)");
  return out;
}

Result<VectorPattern> LoadHpgl(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(const std::string text, ReadPatternFile(path, "plot"));
  return ParseHpgl(text, path);
}

Result<VectorPattern> LoadVectorFile(const std::string& path, double tolerance_mm) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".svg") return LoadSvg(path, tolerance_mm);
  if (ext == ".dxf") return LoadDxf(path, tolerance_mm);
  if (ext == ".plt" || ext == ".hpgl" || ext == ".hpg" || ext == ".hgl") return LoadHpgl(path);
  return InvalidArgument(path + ": not a vector drawing insitu reads (.svg, .dxf, .plt/.hpgl)");
}

namespace {

double JumpLength(const std::vector<Polyline>& paths, Eigen::Vector2d at) {
  double total = 0.0;
  for (const Polyline& p : paths) {
    if (p.points.empty()) continue;
    total += (p.points.front() - at).norm();
    at = p.closed ? p.points.front() : p.points.back();
  }
  return total;
}

}  // namespace

double OrderForTravel(VectorPattern* pattern, const Eigen::Vector2d& start, double* before) {
  std::vector<Polyline>& paths = pattern->paths;
  if (before) *before = JumpLength(paths, start);
  // Greedy nearest entry: O(n^2 + n * points), fine for the thousands of paths
  // of a drawing.
  std::vector<Polyline> ordered;
  std::vector<bool> used(paths.size(), false);
  Eigen::Vector2d at = start;
  for (size_t taken = 0; taken < paths.size(); ++taken) {
    double best = 1e300;
    size_t pick = 0, vertex = 0;
    bool reverse = false;
    for (size_t i = 0; i < paths.size(); ++i) {
      const auto& pts = paths[i].points;
      if (used[i] || pts.empty()) continue;
      if (paths[i].closed) {
        for (size_t k = 0; k < pts.size(); ++k) {
          const double d = (pts[k] - at).squaredNorm();
          if (d < best) best = d, pick = i, vertex = k, reverse = false;
        }
      } else {
        const double d0 = (pts.front() - at).squaredNorm(), d1 = (pts.back() - at).squaredNorm();
        if (d0 < best) best = d0, pick = i, vertex = 0, reverse = false;
        if (d1 < best) best = d1, pick = i, vertex = 0, reverse = true;
      }
    }
    if (best == 1e300) break;  // only empty paths left
    used[pick] = true;
    Polyline p = paths[pick];
    if (reverse) std::reverse(p.points.begin(), p.points.end());
    if (p.closed)
      std::rotate(p.points.begin(), p.points.begin() + static_cast<long>(vertex), p.points.end());
    at = p.closed ? p.points.front() : p.points.back();
    ordered.push_back(std::move(p));
  }
  for (size_t i = 0; i < paths.size(); ++i) {
    if (paths[i].points.empty()) ordered.push_back(paths[i]);
  }
  paths = std::move(ordered);
  return JumpLength(paths, start);
}

std::vector<Segment2> Outline(const VectorPattern& pattern) {
  std::vector<Segment2> out;
  for (const Polyline& p : pattern.paths) {
    for (size_t k = 1; k < p.points.size(); ++k) out.push_back({p.points[k - 1], p.points[k]});
    if (p.closed && p.points.size() >= 3) out.push_back({p.points.back(), p.points.front()});
  }
  return out;
}

Result<std::vector<Segment2>> HatchPolygons(const VectorPattern& pattern, double spacing_mm,
                                            double angle_deg) {
  if (!(spacing_mm > 0)) return InvalidArgument("hatch spacing must be > 0");
  // Work in the hatch frame: lines along x' at y' = k * spacing.
  const double a = angle_deg * M_PI / 180.0;
  const Eigen::Vector2d dir(std::cos(a), std::sin(a)), across(-std::sin(a), std::cos(a));
  std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> edges;  // (x', y') endpoints
  double lo = 1e300, hi = -1e300;
  for (const Polyline& p : pattern.paths) {
    if (!p.closed || p.points.size() < 3) continue;
    for (size_t k = 0; k < p.points.size(); ++k) {
      const Eigen::Vector2d& u = p.points[k];
      const Eigen::Vector2d& v = p.points[(k + 1) % p.points.size()];
      const Eigen::Vector2d uu(u.dot(dir), u.dot(across)), vv(v.dot(dir), v.dot(across));
      edges.emplace_back(uu, vv);
      lo = std::min({lo, uu.y(), vv.y()});
      hi = std::max({hi, uu.y(), vv.y()});
    }
  }
  if (edges.empty()) return InvalidArgument("no closed path to hatch");
  std::vector<Segment2> out;
  bool forward = true;
  for (int k = static_cast<int>(std::ceil(lo / spacing_mm));
       k <= static_cast<int>(std::floor(hi / spacing_mm)); ++k) {
    const double y = k * spacing_mm;
    std::vector<double> xs;
    for (const auto& [u, v] : edges) {
      // Half-open rule on y so a vertex shared by two edges counts once.
      if ((u.y() <= y && v.y() > y) || (v.y() <= y && u.y() > y)) {
        xs.push_back(u.x() + (y - u.y()) / (v.y() - u.y()) * (v.x() - u.x()));
      }
    }
    std::sort(xs.begin(), xs.end());
    std::vector<Segment2> line;
    for (size_t m = 0; m + 1 < xs.size(); m += 2) {
      if (xs[m + 1] - xs[m] < 1e-9) continue;
      line.push_back({xs[m] * dir + y * across, xs[m + 1] * dir + y * across});
    }
    AppendHatchLine(std::move(line), &forward, &out);
  }
  return out;
}

}  // namespace insitu::pattern
