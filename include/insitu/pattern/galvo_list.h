// RTC-style galvo lists: what the marking side emits and a scan head executes.
//
// A list is a sequence of commands on the head's clock (SCANLAB RTC5/RTC6 style): absolute 3D
// jumps and marks (x, y across the field, z the focus height of the dynamic focus unit), jump
// and mark speeds, laser on/off delays, scanner delays (jump, mark, polygon), laser power and
// pulse frequency, and the end of the list. Positions are kept in mm in the galvo frame while a
// list is built; `Emit` turns a finished list into head units (16-bit XY2-100 or 20-bit
// SL2-100 positions, speeds in bits per ms, delays in 10 us ticks) after applying the field
// correction to every point, and refuses any point outside the field or the focus range,
// naming the command, instead of clipping it.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::pattern {

enum class ListOp : uint8_t {
  kJumpAbs,            // p: target, mm
  kMarkAbs,            // p: target, mm (laser on along the way)
  kSetJumpSpeed,       // a: mm/s
  kSetMarkSpeed,       // a: mm/s
  kSetLaserDelays,     // a: laser-on delay, b: laser-off delay, us
  kSetScannerDelays,   // a: jump, b: mark, c: polygon delay, us
  kSetLaserPower,      // a: fraction of full power, 0..1
  kSetLaserFrequency,  // a: pulse repetition frequency, kHz
  kEndOfList,
};

const char* ListOpName(ListOp op);

struct ListCommand {
  ListOp op = ListOp::kEndOfList;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  double a = 0.0, b = 0.0, c = 0.0;
};

// Builds a list in mm; every call checks its own arguments (a negative speed, a NaN point) and
// the first error sticks: Finish() returns it, naming the command's index.
class ListBuilder {
 public:
  ListBuilder& JumpAbs(const Eigen::Vector3d& p_mm);
  ListBuilder& MarkAbs(const Eigen::Vector3d& p_mm);
  ListBuilder& SetJumpSpeed(double mm_per_s);
  ListBuilder& SetMarkSpeed(double mm_per_s);
  ListBuilder& SetLaserDelays(double on_us, double off_us);
  ListBuilder& SetScannerDelays(double jump_us, double mark_us, double polygon_us);
  ListBuilder& SetLaserPower(double fraction);
  ListBuilder& SetLaserFrequency(double khz);

  // Appends the end of the list. Errors: invalid_argument from the first bad call; a list that
  // marks before any mark speed was set; an empty list.
  Result<std::vector<ListCommand>> Finish();

 private:
  ListBuilder& Add(const ListCommand& c, const std::string& problem);
  std::vector<ListCommand> commands_;
  Status error_;
  bool mark_speed_set_ = false;
};

// The head's units and limits.
struct HeadFormat {
  int bits = 16;                       // 16 (XY2-100) or 20 (SL2-100)
  double field_half_size_mm = 80.0;    // full scale: +-(2^(bits-1) - 1) counts
  double focus_half_range_mm = 15.0;   // z full scale likewise
  double clock_us = 10.0;              // delays in ticks of this

  Status Validate() const;
  int64_t max_count() const { return (int64_t{1} << (bits - 1)) - 1; }
  double counts_per_mm() const { return max_count() / field_half_size_mm; }
  double z_counts_per_mm() const { return max_count() / focus_half_range_mm; }
};

// Field correction applied to every emitted point: commanded galvo point (mm) -> the point to
// send so that the spot lands there (mm). Identity when empty.
using FieldCorrection = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

struct EmittedCommand {
  ListOp op = ListOp::kEndOfList;
  int64_t x = 0, y = 0, z = 0;  // counts (jumps and marks)
  int64_t a = 0, b = 0, c = 0;  // speeds: counts per ms; delays: ticks; power: 0..65535;
                                // frequency: Hz
};

// Turns a finished list (ending in kEndOfList) into head units. Errors: out_of_range naming the
// command index, the point (mm, before and after correction) and the limit it breaks;
// invalid_argument for a list without its end or a bad format.
Result<std::vector<EmittedCommand>> Emit(const std::vector<ListCommand>& list,
                                         const HeadFormat& format,
                                         const FieldCorrection& correction = {});

// Text form of an emitted list, one command a line ("mark_abs_3d 1234 -567 89"), with the
// format in a header: the galvo-list artifact of a job.
std::string FormatEmitted(const std::vector<EmittedCommand>& list, const HeadFormat& format);

// Marking time of a list at its speeds and delays (jumps at jump speed, marks at mark speed,
// plus the scanner delays after each move), seconds: for progress estimates and reports.
double ListDuration(const std::vector<ListCommand>& list);

}  // namespace insitu::pattern
