// EzCad correction files (.cor) for LMC boards, both formats, so an existing machine's field
// correction can be imported into insitu and insitu's exported to the board.
//
//   "JCZ_COR_2_1" (33,840 bytes): a 22-byte label, 6 bytes, the scale (double, units per mm) at
//                 0x1C, then 65 x 65 (dx, dy) int32 pairs from 0x24, x outer, and 4 bytes.
//   "LMC1COR_1.0": a 22-byte label, 2 bytes, 63 doubles (the scale is the 44th), then 65 x 65
//                 (dx, dy) double pairs.
// The 22-byte labels are UTF-16LE as EzCad writes them (8-bit labels are read too). The 65 x 65
// nodes span the board's 65536 units (node i at i * 1024 units); the lens field is
// 65536 / scale mm. Offsets are what is uploaded for the node (WriteCorLine), in units, as
// stored in both formats, within the board's +-32767 (docs/hardware.md says where these facts
// come from and what was not verified on a board).
#pragma once

#include <Eigen/Core>
#include <array>
#include <functional>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/lmc.h"

namespace insitu::hw::lmc {

enum class CorFormat { kJcz2, kLmc1 };

struct CorFile {
  CorFormat format = CorFormat::kJcz2;
  double scale = 65536.0 / 110.0;              // units per mm
  std::vector<std::array<double, 2>> offsets;  // 65 x 65, x outer, units

  double lens_mm() const { return 65536.0 / scale; }
  // Galvo-frame position (mm) of node (i, j), i along x.
  Eigen::Vector2d NodeMm(int i, int j) const;
};

// Errors: not_found (cannot read), parse_error naming the file and what is wrong (label, size,
// scale, a non-finite offset).
Result<CorFile> ReadCor(const std::string& path);
// Errors: out_of_range (an offset beyond +-32767 or not finite), device_error (cannot write).
Status WriteCor(const std::string& path, const CorFile& cor);

// The table for the board (rounded to whole units).
BoardCorrection ToBoard(const CorFile& cor);
// As insitu's field correction CSV (pattern::CorrectionTable: x_mm, y_mm, dx_mm, dy_mm).
std::string ToCorrectionCsv(const CorFile& cor);
// From a correction in the galvo frame: offset_mm(x, y) at every node of a lens_mm field.
CorFile FromCorrection(const std::function<Eigen::Vector2d(double, double)>& offset_mm,
                       double lens_mm, CorFormat format);

}  // namespace insitu::hw::lmc
