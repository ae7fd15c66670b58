#include "insitu/pattern/correction_table.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include "pattern/flatten.h"

namespace insitu::pattern {
namespace {

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) {
    const auto b = cell.find_first_not_of(" \t\r"), e = cell.find_last_not_of(" \t\r");
    out.push_back(b == std::string::npos ? "" : cell.substr(b, e - b + 1));
  }
  return out;
}

// Index of v in the ascending list (values within 1e-9 mm are one node).
int IndexOf(const std::vector<double>& list, double v) {
  const auto it = std::lower_bound(list.begin(), list.end(), v - 1e-9);
  return static_cast<int>(it - list.begin());
}

}  // namespace

Result<CorrectionTable> CorrectionTable::Parse(const std::string& text, const std::string& origin) {
  std::stringstream in(text);
  std::string line;
  int line_no = 0;
  std::map<std::string, int> column;
  struct Row {
    double x, y, dx, dy;
    int line;
  };
  std::vector<Row> rows;
  const char* names[4] = {"x_mm", "y_mm", "dx_mm", "dy_mm"};
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    const std::vector<std::string> cells = SplitCsv(line);
    const std::string where = origin + ":" + std::to_string(line_no);
    if (column.empty()) {
      for (size_t i = 0; i < cells.size(); ++i) {
        if (!column.emplace(cells[i], static_cast<int>(i)).second) {
          return ParseError(where + ": column '" + cells[i] + "' appears twice in the header");
        }
      }
      for (const char* n : names) {
        if (!column.count(n)) {
          return ParseError(where + ": the header has no column '" + n +
                            "' (needs x_mm, y_mm, dx_mm, dy_mm)");
        }
      }
      continue;
    }
    double v[4];
    for (int k = 0; k < 4; ++k) {
      const int c = column[names[k]];
      if (c >= static_cast<int>(cells.size())) {
        return ParseError(where + ": column " + names[k] + " is missing");
      }
      char* end = nullptr;
      v[k] = std::strtod(cells[c].c_str(), &end);
      if (cells[c].empty() || end != cells[c].c_str() + cells[c].size() || !std::isfinite(v[k])) {
        return ParseError(where + ": " + names[k] + ": '" + cells[c] + "' is not a finite number");
      }
    }
    rows.push_back({v[0], v[1], v[2], v[3], line_no});
  }
  if (column.empty()) return InvalidArgument(origin + ": no header row (x_mm, y_mm, dx_mm, dy_mm)");
  CorrectionTable t;
  for (const Row& r : rows) {
    for (auto [list, v] : {std::pair{&t.xs_, r.x}, std::pair{&t.ys_, r.y}}) {
      if (std::none_of(list->begin(), list->end(),
                       [&](double u) { return std::abs(u - v) < 1e-9; })) {
        list->push_back(v);
      }
    }
  }
  std::sort(t.xs_.begin(), t.xs_.end());
  std::sort(t.ys_.begin(), t.ys_.end());
  if (t.xs_.size() < 2 || t.ys_.size() < 2) {
    return InvalidArgument(origin + ": a correction grid needs at least 2 x 2 nodes, got " +
                           std::to_string(t.xs_.size()) + " x " + std::to_string(t.ys_.size()));
  }
  const size_t nx = t.xs_.size();
  t.offset_.assign(nx * t.ys_.size(), Eigen::Vector2d::Constant(NAN));
  for (const Row& r : rows) {
    Eigen::Vector2d& o = t.offset_[IndexOf(t.ys_, r.y) * nx + IndexOf(t.xs_, r.x)];
    if (!std::isnan(o.x())) {
      return InvalidArgument(origin + ":" + std::to_string(r.line) + ": node (" +
                             std::to_string(r.x) + ", " + std::to_string(r.y) + ") appears twice");
    }
    o = {r.dx, r.dy};
  }
  for (size_t j = 0; j < t.ys_.size(); ++j) {
    for (size_t i = 0; i < nx; ++i) {
      if (std::isnan(t.offset_[j * nx + i].x())) {
        return InvalidArgument(origin + ": the grid has no node at (" + std::to_string(t.xs_[i]) +
                               ", " + std::to_string(t.ys_[j]) + ") mm");
      }
    }
  }
  return t;
}

Result<CorrectionTable> CorrectionTable::Load(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(std::string text, ReadPatternFile(path, "correction table"));
  return Parse(text, path);
}

Eigen::Vector2d CorrectionTable::OffsetAt(double x, double y) const {
  const auto cell = [](const std::vector<double>& v, double q, double* f) {
    const double c = std::clamp(q, v.front(), v.back());
    int i = static_cast<int>(std::upper_bound(v.begin(), v.end(), c) - v.begin()) - 1;
    i = std::clamp(i, 0, static_cast<int>(v.size()) - 2);
    *f = (c - v[i]) / (v[i + 1] - v[i]);
    return i;
  };
  double fx, fy;
  const int i = cell(xs_, x, &fx), j = cell(ys_, y, &fy);
  const size_t nx = xs_.size();
  const auto at = [&](int a, int b) { return offset_[static_cast<size_t>(b) * nx + a]; };
  return (1 - fy) * ((1 - fx) * at(i, j) + fx * at(i + 1, j)) +
         fy * ((1 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1));
}

FieldCorrection CorrectionTable::AsFieldCorrection() const {
  return [table = *this](const Eigen::Vector3d& p) {
    const Eigen::Vector2d d = table.OffsetAt(p.x(), p.y());
    return Eigen::Vector3d(p.x() + d.x(), p.y() + d.y(), p.z());
  };
}

}  // namespace insitu::pattern
