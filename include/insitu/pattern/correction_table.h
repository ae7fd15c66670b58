// A field correction table for the galvo list (seed 003 sec. 2.1: the
// correction applies to every emitted point): on a regular grid of commanded
// galvo points, the offset to add so the spot lands where it was asked for.
// Between nodes the offset is bilinear; beyond the grid it is the nearest
// edge's (the field check after correction still refuses what leaves the head's
// range). Galvo frame, mm; z passes unchanged.
//
// File (CSV): a header row naming x_mm, y_mm, dx_mm, dy_mm (any order; other
// columns are ignored), then one row per grid node; `#` lines are comments.
// Every combination of the distinct x and y values must appear exactly once (at
// least 2 x 2).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/optics/grid_table.h"
#include "insitu/pattern/galvo_list.h"

namespace insitu::pattern {

class CorrectionTable {
 public:
  // Errors (parse_error / invalid_argument) name the file, the line and the
  // column: missing columns, duplicate headers, non-numbers, NaN, a node twice
  // or missing, fewer than 2 x 2.
  static Result<CorrectionTable> Parse(const std::string& text, const std::string& origin);
  static Result<CorrectionTable> Load(const std::string& path);

  Eigen::Vector2d OffsetAt(double x_mm, double y_mm) const;
  // As a FieldCorrection for Emit().
  FieldCorrection AsFieldCorrection() const;

  int nodes_x() const { return static_cast<int>(table_.xs().size()); }
  int nodes_y() const { return static_cast<int>(table_.ys().size()); }
  // A table of offsets already on a grid (a correction computed by a field calibration).
  explicit CorrectionTable(optics::GridTable table) : table_(std::move(table)) {}
  const optics::GridTable& table() const { return table_; }
  // As CSV in the format Parse reads.
  std::string ToCsv() const;

 private:
  CorrectionTable() = default;
  optics::GridTable table_;  // offsets dx, dy
};

}  // namespace insitu::pattern
