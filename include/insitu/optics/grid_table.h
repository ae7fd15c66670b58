// A vector field on a regular grid, bilinear between nodes and the nearest edge's value beyond
// them: seed 003's n x n lookup (eq. 12-13) and seed 001's interpolated compensation table.
// Used for field errors (meas - cmd), corrections (offsets to add to a command) and what the
// physical head model leaves. Galvo frame, mm.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::optics {

class GridTable {
 public:
  GridTable() = default;
  // xs, ys ascending (>= 2 each), values row-major (iy * xs.size() + ix), all finite.
  // Errors: invalid_argument naming what is wrong.
  static Result<GridTable> Make(std::vector<double> xs, std::vector<double> ys,
                                std::vector<Eigen::Vector2d> values);
  bool empty() const { return xs_.empty(); }
  Eigen::Vector2d At(double x_mm, double y_mm) const;
  const std::vector<double>& xs() const { return xs_; }
  const std::vector<double>& ys() const { return ys_; }
  const std::vector<Eigen::Vector2d>& values() const { return values_; }

 private:
  std::vector<double> xs_, ys_;
  std::vector<Eigen::Vector2d> values_;
};

}  // namespace insitu::optics
