#include "insitu/fit/field_data.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string_view>

namespace insitu::fit {
namespace {

constexpr double kSamePositionMm = 1e-9;

// The used columns: the four required ones first, then the optional ones.
enum Used { kXCmd, kYCmd, kXMeas, kYMeas, kZCmd, kT, kVx, kVy, kNumUsed };
constexpr const char* kUsedName[kNumUsed] = {"x_cmd_mm", "y_cmd_mm", "x_meas_mm", "y_meas_mm",
                                             "z_cmd_mm", "t_s",      "vx_mm_s",   "vy_mm_s"};
constexpr const char* kRequiredList = "x_cmd_mm, y_cmd_mm, x_meas_mm, y_meas_mm";

std::string_view Trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

// Unlike std::getline on ',', keeps a trailing empty cell, so "1,2," has three cells and a
// short or over-long row is seen as such.
std::vector<std::string> SplitCells(std::string_view line) {
  std::vector<std::string> cells;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    const size_t end = comma == std::string_view::npos ? line.size() : comma;
    cells.emplace_back(Trim(line.substr(start, end - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return cells;
}

// The whole cell must be the number: std::strtod alone accepts "1.5mm" as 1.5.
std::optional<double> ToDouble(const std::string& cell) {
  if (cell.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(cell.c_str(), &end);
  if (end != cell.c_str() + cell.size()) return std::nullopt;
  return v;
}

bool SamePosition(const FieldPoint& a, const FieldPoint& b, bool use_z) {
  return std::abs(a.cmd.x() - b.cmd.x()) <= kSamePositionMm &&
         std::abs(a.cmd.y() - b.cmd.y()) <= kSamePositionMm &&
         (!use_z || std::abs(a.z_cmd_mm - b.z_cmd_mm) <= kSamePositionMm);
}

// Groups of point indices by commanded position, in order of first occurrence. A point joins
// the first group whose first point is within tolerance, so the grouping does not depend on
// chains of near-equal positions. O(points x groups), fine for hand-measured data sets.
std::vector<std::vector<int>> GroupByPosition(const FieldData& data) {
  std::vector<std::vector<int>> groups;
  for (int i = 0; i < static_cast<int>(data.points.size()); ++i) {
    bool placed = false;
    for (std::vector<int>& g : groups) {
      if (SamePosition(data.points[g.front()], data.points[i], data.has_z)) {
        g.push_back(i);
        placed = true;
        break;
      }
    }
    if (!placed) groups.push_back({i});
  }
  return groups;
}

}  // namespace

std::vector<std::vector<int>> FieldData::ReplicateGroups() const {
  std::vector<std::vector<int>> replicates;
  for (std::vector<int>& g : GroupByPosition(*this)) {
    if (g.size() >= 2) replicates.push_back(std::move(g));
  }
  return replicates;
}

int FieldData::DistinctPositions() const { return static_cast<int>(GroupByPosition(*this).size()); }

Result<FieldData> ParseFieldCsv(const std::string& text, const std::string& origin) {
  FieldData data;
  data.origin = origin;

  std::vector<std::string> header;
  int header_line = 0;
  std::map<std::string, int> column;  // name -> index in the row
  // Index in the row of each used column (-1 when absent), and of the extra columns.
  int used[kNumUsed];
  std::fill(std::begin(used), std::end(used), -1);
  std::vector<std::pair<int, std::vector<double>*>> extra_columns;

  std::string_view rest(text);
  // A UTF-8 byte order mark (spreadsheet exports) would otherwise be part of the first name.
  if (rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);
  int line_no = 0;
  while (!rest.empty()) {
    const size_t nl = rest.find('\n');
    const std::string_view raw = rest.substr(0, nl);
    rest.remove_prefix(nl == std::string_view::npos ? rest.size() : nl + 1);
    ++line_no;
    const std::string_view line = Trim(raw);
    if (line.empty() || line.front() == '#') continue;
    const std::string where = origin + ":" + std::to_string(line_no) + ": ";
    std::vector<std::string> cells = SplitCells(line);

    if (header.empty()) {
      header_line = line_no;
      for (size_t i = 0; i < cells.size(); ++i) {
        if (cells[i].empty()) {
          return ParseError(where + "header column " + std::to_string(i + 1) +
                            " has no name (required columns: " + kRequiredList + ")");
        }
        const auto [it, inserted] = column.emplace(cells[i], static_cast<int>(i));
        if (!inserted) {
          return ParseError(where + "column '" + cells[i] +
                            "' appears twice in the header (columns " +
                            std::to_string(it->second + 1) + " and " + std::to_string(i + 1) + ")");
        }
      }
      std::string missing;
      for (int k = kXCmd; k <= kYMeas; ++k) {
        if (!column.count(kUsedName[k]))
          missing += std::string(missing.empty() ? "" : ", ") + "'" + kUsedName[k] + "'";
      }
      if (!missing.empty()) {
        return ParseError(where + "the header has no column " + missing +
                          " (required columns: " + kRequiredList + ")");
      }
      for (int k = 0; k < kNumUsed; ++k) {
        if (const auto it = column.find(kUsedName[k]); it != column.end()) used[k] = it->second;
      }
      if ((used[kVx] < 0) != (used[kVy] < 0)) {
        const char* present = kUsedName[used[kVx] >= 0 ? kVx : kVy];
        const char* absent = kUsedName[used[kVx] >= 0 ? kVy : kVx];
        return InvalidArgument(where + "column '" + present + "' without column '" + absent +
                               "' (the beam velocity needs both or neither)");
      }
      data.has_z = used[kZCmd] >= 0;
      data.has_t = used[kT] >= 0;
      data.has_v = used[kVx] >= 0;
      for (size_t i = 0; i < cells.size(); ++i) {
        if (std::find(std::begin(used), std::end(used), static_cast<int>(i)) == std::end(used)) {
          extra_columns.emplace_back(static_cast<int>(i), &data.extra[cells[i]]);
        }
      }
      header = std::move(cells);
      continue;
    }

    if (cells.size() < header.size()) {
      return ParseError(where + "the row has " + std::to_string(cells.size()) +
                        " cells, the header has " + std::to_string(header.size()) +
                        ": no value for column '" + header[cells.size()] + "'");
    }
    if (cells.size() > header.size()) {
      return ParseError(where + "the row has " + std::to_string(cells.size()) +
                        " cells, the header has " + std::to_string(header.size()) + " (column " +
                        std::to_string(header.size() + 1) + " has no name)");
    }
    double v[kNumUsed] = {};  // an absent optional column reads as 0
    for (int k = 0; k < kNumUsed; ++k) {
      if (used[k] < 0) continue;
      const std::string& cell = cells[used[k]];
      const std::string& name = header[used[k]];
      if (cell.empty()) {
        return ParseError(where + "column '" + name + "' is empty, expected a number");
      }
      const std::optional<double> x = ToDouble(cell);
      if (!x) {
        return ParseError(where + "column '" + name + "': '" + cell + "' is not a number");
      }
      if (!std::isfinite(*x)) {
        return ParseError(where + "column '" + name + "': '" + cell + "' is not a finite number");
      }
      v[k] = *x;
    }
    FieldPoint p;
    p.cmd = {v[kXCmd], v[kYCmd]};
    p.meas = {v[kXMeas], v[kYMeas]};
    p.z_cmd_mm = v[kZCmd];
    p.t_s = v[kT];
    p.v_mm_s = {v[kVx], v[kVy]};
    p.line = line_no;
    data.points.push_back(p);
    for (auto& [index, values] : extra_columns) {
      values->push_back(ToDouble(cells[index]).value_or(std::numeric_limits<double>::quiet_NaN()));
    }
  }

  if (header.empty()) {
    // An empty file still has a line 1 in an editor.
    return ParseError(
        origin + ":" + std::to_string(std::max(line_no, 1)) +
        ": no header row before the end of the file (required columns: " + kRequiredList + ")");
  }
  if (data.points.empty()) {
    return InvalidArgument(origin + ":" + std::to_string(line_no) +
                           ": no data rows after the header on line " +
                           std::to_string(header_line) + " (columns " + kRequiredList + ")");
  }
  if (const auto it = data.extra.find("move_reference"); it != data.extra.end()) {
    for (size_t i = 0; i < it->second.size(); ++i) {
      const double r = it->second[i];
      const std::string where = origin + ":" + std::to_string(data.points[i].line) + ": ";
      if (r != 0.0 && r != 1.0) {
        return ParseError(where +
                          "column 'move_reference' must be 0 or 1 (1 on the row the others "
                          "were measured from)");
      }
      if (r == 1.0 && data.reference >= 0) {
        return InvalidArgument(where + "a second row marked reference (the first on line " +
                               std::to_string(data.points[data.reference].line) +
                               "): the moves are measured from one position");
      }
      if (r == 1.0) data.reference = static_cast<int>(i);
    }
  }
  return data;
}

Result<FieldData> LoadFieldCsv(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return NotFound(path + ": is a directory, expected a galvo field CSV file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return NotFound(path + ": cannot open (" + std::strerror(errno) +
                    "), expected a galvo field CSV file");
  }
  std::ostringstream text;
  text << in.rdbuf();
  return ParseFieldCsv(text.str(), path);
}

}  // namespace insitu::fit
