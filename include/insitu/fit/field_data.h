// Measured galvo field data: commanded positions and where the spot was measured (CONTRACT.md,
// "Galvo field data"). Units mm, s, mm/s; the galvo frame of the data set (its commanded origin
// need not be the optical axis).
//
// CSV: a header row, then one row per measurement; lines starting with `#` are comments.
// Required columns: x_cmd_mm, y_cmd_mm, x_meas_mm, y_meas_mm. Optional: z_cmd_mm (focus
// shift), t_s (time since start), vx_mm_s and vy_mm_s (beam velocity at the measurement; both
// or neither), move_reference (0 or 1: the row a table of moves was measured from; see
// FieldData::reference). Other columns are kept by name and ignored by the fits. Repeated
// commanded positions are replicates.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::fit {

struct FieldPoint {
  Eigen::Vector2d cmd = Eigen::Vector2d::Zero();   // x_cmd_mm, y_cmd_mm
  Eigen::Vector2d meas = Eigen::Vector2d::Zero();  // x_meas_mm, y_meas_mm
  double z_cmd_mm = 0.0;                           // 0 when the column is absent
  double t_s = 0.0;
  Eigen::Vector2d v_mm_s = Eigen::Vector2d::Zero();
  int line = 0;  // line of the file (1-based), for messages
};

struct FieldData {
  std::string origin;  // file name or "<generated>"
  std::vector<FieldPoint> points;
  bool has_z = false, has_t = false, has_v = false;
  // Columns beyond the known ones, by name: one value per point (NaN where not a number).
  std::map<std::string, std::vector<double>> extra;
  // A table of moves (optional column `move_reference`, 1 on one row): the measured positions are
  // displacements from where the spot was measured at that row's command, so that row reads
  // meas = cmd by definition and carries no measurement, and its own measuring error is common
  // to every other row. -1: absolute positions.
  int reference = -1;

  // Indices of points sharing a commanded position (x, y and, with has_z, z equal within
  // 1e-9 mm), only groups of two or more: the replicates.
  std::vector<std::vector<int>> ReplicateGroups() const;
  // Distinct commanded positions.
  int DistinctPositions() const;
};

// Errors (parse_error / invalid_argument), each naming the origin, the line and the column:
// missing required columns, a column named twice, a non-number or NaN/inf in a used column,
// vx without vy (or the reverse), no data rows.
Result<FieldData> ParseFieldCsv(const std::string& text, const std::string& origin);
// Errors: not_found for a missing file, then those of ParseFieldCsv.
Result<FieldData> LoadFieldCsv(const std::string& path);

}  // namespace insitu::fit
