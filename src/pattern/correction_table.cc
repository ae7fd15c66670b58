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
  std::vector<double> xs, ys;
  for (const Row& r : rows) {
    for (const auto& [list, value] : {std::pair{&xs, r.x}, std::pair{&ys, r.y}}) {
      const double v = value;  // (a structured binding is not captured by clang 14's lambdas)
      if (std::none_of(list->begin(), list->end(),
                       [&](double u) { return std::abs(u - v) < 1e-9; })) {
        list->push_back(v);
      }
    }
  }
  std::sort(xs.begin(), xs.end());
  std::sort(ys.begin(), ys.end());
  if (xs.size() < 2 || ys.size() < 2) {
    return InvalidArgument(origin + ": a correction grid needs at least 2 x 2 nodes, got " +
                           std::to_string(xs.size()) + " x " + std::to_string(ys.size()));
  }
  const size_t nx = xs.size();
  std::vector<Eigen::Vector2d> offset(nx * ys.size(), Eigen::Vector2d::Constant(NAN));
  for (const Row& r : rows) {
    Eigen::Vector2d& o = offset[IndexOf(ys, r.y) * nx + IndexOf(xs, r.x)];
    if (!std::isnan(o.x())) {
      return InvalidArgument(origin + ":" + std::to_string(r.line) + ": node (" +
                             std::to_string(r.x) + ", " + std::to_string(r.y) + ") appears twice");
    }
    o = {r.dx, r.dy};
  }
  for (size_t j = 0; j < ys.size(); ++j) {
    for (size_t i = 0; i < nx; ++i) {
      if (std::isnan(offset[j * nx + i].x())) {
        return InvalidArgument(origin + ": the grid has no node at (" + std::to_string(xs[i]) +
                               ", " + std::to_string(ys[j]) + ") mm");
      }
    }
  }
  INSITU_ASSIGN_OR_RETURN(t.table_, optics::GridTable::Make(std::move(xs), std::move(ys),
                                                            std::move(offset)));
  return t;
}

Result<CorrectionTable> CorrectionTable::Load(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(std::string text, ReadPatternFile(path, "correction table"));
  return Parse(text, path);
}

Eigen::Vector2d CorrectionTable::OffsetAt(double x, double y) const { return table_.At(x, y); }

std::string CorrectionTable::ToCsv() const {
  std::ostringstream os;
  os.precision(10);
  os << "# insitu field correction: offset to add to a commanded galvo point (mm)\n"
     << "x_mm,y_mm,dx_mm,dy_mm\n";
  const size_t nx = table_.xs().size();
  for (size_t j = 0; j < table_.ys().size(); ++j) {
    for (size_t i = 0; i < nx; ++i) {
      const Eigen::Vector2d& d = table_.values()[j * nx + i];
      os << table_.xs()[i] << "," << table_.ys()[j] << "," << d.x() << "," << d.y() << "\n";
    }
  }
  return os.str();
}

FieldCorrection CorrectionTable::AsFieldCorrection() const {
  return [table = *this](const Eigen::Vector3d& p) {
    const Eigen::Vector2d d = table.OffsetAt(p.x(), p.y());
    return Eigen::Vector3d(p.x() + d.x(), p.y() + d.y(), p.z());
  };
}

}  // namespace insitu::pattern
