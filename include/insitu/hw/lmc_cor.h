// EzCad correction files (.cor) for LMC boards, both formats, so an existing machine's field
// correction can be imported into insitu and insitu's exported to the board.
//
//   "JCZ_COR_2_1" (33,840 bytes): a 22-byte label, 6 bytes, the scale (double, units per mm) at
//                 0x1C, then 65 x 65 int32 pairs from 0x24, and 4 bytes.
//   "LMC1COR_1.0": a 22-byte label, 2 bytes, 63 doubles (the scale is the 44th), then 65 x 65
//                 double pairs.
// The 22-byte labels are UTF-16LE as EzCad writes them (8-bit labels are read too). The 65 x 65
// nodes span the board's 65536 units (node i at i * 1024 units); the lens field is
// 65536 / scale mm. The stored pairs are what is uploaded for the node (WriteCorLine), in
// units, within the board's +-32767 (docs/hardware.md says where these facts come from and
// what was not verified on a board).
//
// What the sources do not agree on is how a stored pair maps onto the field: meerk40t reads
// the nodes x outer and the pair as (dx, dy); glase documents the pair as (dy, dx) with x
// outer, the stored value the error the board SUBTRACTS, and its x is the board's second word
// (glase sends positions as (y, x)). In the board's words that is: the inner index walks word
// 1, the outer word 2, a pair is (error along word 1, error along word 2). Real EzCad tables
// agree with that structure exactly (the first element is zero wherever the inner index is at
// the centre, the second wherever the outer is), and the two-mirror head explains them in it
// (docs/hardware.md, ".cor files"). A CorReading names one convention (node order, pair order,
// the sign of each component) in insitu's galvo frame; CorFile keeps the numbers exactly as
// stored and a reading is applied only where a table meets the galvo frame (OffsetMm,
// ToCorrectionCsv, FromCorrection). `insitu cor import` lets the two-mirror head model choose
// the reading, and the documented convention decide what the physics cannot
// (fit/cor_physics.h, job/cor_reading.h).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/lmc_options.h"

namespace insitu::hw::lmc {

enum class CorFormat { kJcz2, kLmc1 };

// How the stored numbers of a table are insitu's offsets (galvo frame: dx along x, dy along
// y, the offset to ADD to a command at the node). A default-constructed reading is meerk40t's:
// nodes x outer, pair (dx, dy), signs as stored (which real tables contradict: it is only a
// name here, never a fallback).
struct CorReading {
  bool y_major = false;     // stored with y outer: entry j * 65 + i is node (i, j), i along x
  bool pair_dy_dx = false;  // a stored pair is (dy, dx)
  bool negate_dx = false;   // the stored dx is -dx
  bool negate_dy = false;

  // "pair (dy, dx), x-major, signs (+,-)": signs of (dx, dy).
  std::string Name() const;
  // What --reading takes: "dy-dx,x-major,+-".
  std::string Code() const;
  bool operator==(const CorReading& o) const {
    return y_major == o.y_major && pair_dy_dx == o.pair_dy_dx && negate_dx == o.negate_dx &&
           negate_dy == o.negate_dy;
  }
  bool operator!=(const CorReading& o) const { return !(*this == o); }
};

// Parses a reading's code: comma-separated, any order, each part at most once, missing parts
// as the default: pair "dx-dy" or "dy-dx", node order "x-major" or "y-major", signs "++",
// "+-", "-+" or "--" (of dx, dy). Errors: invalid_argument naming the part not understood.
Result<CorReading> ParseCorReading(const std::string& code);
// The 16 readings, meerk40t's first.
std::vector<CorReading> AllCorReadings();

// The documented convention (above) read into insitu's galvo frame, for a board whose word 1
// drives galvo x, the first mirror (first_mirror_on_word2 false: lmc.swap_xy false): nodes y
// outer, pair (dx, dy), both negated; or whose word 2 does (lmc.swap_xy true): nodes x outer,
// pair (dy, dx), both negated. The two differ by a transposition only, which the two-mirror
// head tells apart.
CorReading DocumentedReading(bool first_mirror_on_word2);
// One of the two.
bool IsDocumentedReading(const CorReading& reading);
// For a documented reading: whether the head's first mirror is on the board's word 2.
bool FirstMirrorOnWord2(const CorReading& reading);

struct CorFile {
  CorFormat format = CorFormat::kJcz2;
  double scale = 65536.0 / 110.0;              // units per mm
  std::vector<std::array<double, 2>> offsets;  // 65 x 65 pairs in file order, units, as stored
  // The bytes before the table and after it, as read (label, padding, other header fields),
  // so that a file read and written again is the same file. Empty: written as insitu writes
  // them (the label, zeros, the scale).
  std::string header, trailer;

  double lens_mm() const { return 65536.0 / scale; }
  // Galvo-frame position (mm) of node (i, j), i along x.
  Eigen::Vector2d NodeMm(int i, int j) const;
  // The offset (mm, galvo frame) at node (i, j) when the file is read as `reading`.
  Eigen::Vector2d OffsetMm(int i, int j, const CorReading& reading = {}) const;
};

// The numbers as stored; a reading applies to what is made of them. Errors: not_found (cannot
// read), parse_error naming the file and what is wrong (label, size, scale, a non-finite or
// out-of-range offset and its node).
Result<CorFile> ReadCor(const std::string& path);
// Errors: invalid_argument (not 65 x 65 pairs), out_of_range (an offset beyond +-32767 or not
// finite), device_error (cannot write). A CorFile as ReadCor returned it is written back byte
// for byte.
Status WriteCor(const std::string& path, const CorFile& cor);

// A board's position words (0..65536, the field's centre at 32768, not rounded) for a point of
// the galvo frame (mm), as a board set up as `board` (lens, swap_xy, flip_x, flip_y) maps them;
// and back. The encoder's ToUnits rounds the first, the emulator and the tables use both.
Eigen::Vector2d BoardWordsOf(const Eigen::Vector2d& point_mm, const BoardOptions& board);
Eigen::Vector2d GalvoMmOf(const Eigen::Vector2d& words, const BoardOptions& board);

// The table a board set up as `board` (lens, swap_xy, flip_x, flip_y) needs so that a command
// p (galvo frame, mm) reaches the galvos as drive_mm(p): built node by node in the board's own
// words (node k at inner k % 65 along word 1, outer k / 65 along word 2, as the board applies
// it) and stored in the documented convention (the error the board subtracts), whole units.
// With no flips it is FromCorrection(drive - p, DocumentedReading(swap_xy)); with flips only
// this one is right. A non-finite drive is kept for WriteCor to refuse.
CorFile BoardTableFromDrive(const std::function<Eigen::Vector2d(const Eigen::Vector2d&)>& drive_mm,
                            const BoardOptions& board, CorFormat format);

// A correction table as the board takes it: 65 x 65 (dx, dy) offsets in units, x outer.
struct BoardCorrection {
  std::vector<std::array<int32_t, 2>> offsets;  // 4225
};

// The table for the board as stored (rounded to whole units): the board takes the file in its
// own convention, whatever reading insitu used to understand it.
BoardCorrection ToBoard(const CorFile& cor);
// As insitu's field correction CSV (pattern::CorrectionTable: x_mm, y_mm, dx_mm, dy_mm) when
// read as `reading`; its comment lines name the file's format, lens and the reading
// ("# reading: dy-dx,x-major,++"), which `insitu cor export` uses to write the table back.
std::string ToCorrectionCsv(const CorFile& cor, const CorReading& reading = {});
// The reading a correction CSV's "# reading:" comment names; nullopt without one. Errors:
// invalid_argument (the comment does not parse), naming `origin`.
Result<std::optional<CorReading>> CorReadingOfCsv(const std::string& text,
                                                  const std::string& origin);
// From a correction in the galvo frame: offset_mm(x, y) at every node of a lens_mm field,
// stored as `reading` in whole units (what a WriteCorLine carries; so an exported table read
// back and exported again is the same file in both formats). A table for a board is stored in
// DocumentedReading(its swap_xy).
CorFile FromCorrection(const std::function<Eigen::Vector2d(double, double)>& offset_mm,
                       double lens_mm, CorFormat format, const CorReading& reading);

}  // namespace insitu::hw::lmc
