#include "insitu/optics/grid_table.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace insitu::optics {

Result<GridTable> GridTable::Make(std::vector<double> xs, std::vector<double> ys,
                                  std::vector<Eigen::Vector2d> values) {
  if (xs.size() < 2 || ys.size() < 2) {
    return InvalidArgument("a grid table needs at least 2 x 2 nodes, got " +
                           std::to_string(xs.size()) + " x " + std::to_string(ys.size()));
  }
  for (const std::vector<double>* v : {&xs, &ys}) {
    for (size_t i = 0; i < v->size(); ++i) {
      if (!std::isfinite((*v)[i]) || (i > 0 && !((*v)[i] > (*v)[i - 1]))) {
        return InvalidArgument("grid table node coordinates must be finite and ascending");
      }
    }
  }
  if (values.size() != xs.size() * ys.size()) {
    return InvalidArgument("a " + std::to_string(xs.size()) + " x " + std::to_string(ys.size()) +
                           " grid table needs " + std::to_string(xs.size() * ys.size()) +
                           " values, got " + std::to_string(values.size()));
  }
  for (const Eigen::Vector2d& v : values) {
    if (!v.allFinite()) return InvalidArgument("grid table values must be finite");
  }
  GridTable t;
  t.xs_ = std::move(xs);
  t.ys_ = std::move(ys);
  t.values_ = std::move(values);
  return t;
}

Eigen::Vector2d GridTable::At(double x, double y) const {
  if (empty()) return Eigen::Vector2d::Zero();
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
  const auto at = [&](int a, int b) { return values_[static_cast<size_t>(b) * nx + a]; };
  return (1 - fy) * ((1 - fx) * at(i, j) + fx * at(i + 1, j)) +
         fy * ((1 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1));
}

}  // namespace insitu::optics
