#include "insitu/pattern/galvo_list.h"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace insitu::pattern {

const char* ListOpName(ListOp op) {
  switch (op) {
    case ListOp::kJumpAbs: return "jump_abs_3d";
    case ListOp::kMarkAbs: return "mark_abs_3d";
    case ListOp::kSetJumpSpeed: return "set_jump_speed";
    case ListOp::kSetMarkSpeed: return "set_mark_speed";
    case ListOp::kSetLaserDelays: return "set_laser_delays";
    case ListOp::kSetScannerDelays: return "set_scanner_delays";
    case ListOp::kSetLaserPower: return "set_laser_power";
    case ListOp::kSetLaserFrequency: return "set_laser_frequency";
    case ListOp::kEndOfList: return "set_end_of_list";
  }
  return "?";
}

ListBuilder& ListBuilder::Add(const ListCommand& c, const std::string& problem) {
  if (error_.ok() && !problem.empty()) {
    error_ = InvalidArgument("list command " + std::to_string(commands_.size()) + " (" +
                             ListOpName(c.op) + "): " + problem);
  }
  commands_.push_back(c);
  return *this;
}

namespace {

std::string PointProblem(const Eigen::Vector3d& p) {
  return p.allFinite() ? "" : "the point is not a number";
}

std::string PositiveProblem(double v, const char* what) {
  return std::isfinite(v) && v > 0 ? "" : std::string(what) + " must be > 0";
}

std::string NonNegativeProblem(double v, const char* what) {
  return std::isfinite(v) && v >= 0 ? "" : std::string(what) + " must be >= 0";
}

}  // namespace

ListBuilder& ListBuilder::JumpAbs(const Eigen::Vector3d& p) {
  return Add({ListOp::kJumpAbs, p}, PointProblem(p));
}

ListBuilder& ListBuilder::MarkAbs(const Eigen::Vector3d& p) {
  std::string problem = PointProblem(p);
  if (problem.empty() && !mark_speed_set_) problem = "marks before any set_mark_speed";
  return Add({ListOp::kMarkAbs, p}, problem);
}

ListBuilder& ListBuilder::SetJumpSpeed(double v) {
  return Add({ListOp::kSetJumpSpeed, {}, v}, PositiveProblem(v, "jump speed"));
}

ListBuilder& ListBuilder::SetMarkSpeed(double v) {
  mark_speed_set_ = true;
  return Add({ListOp::kSetMarkSpeed, {}, v}, PositiveProblem(v, "mark speed"));
}

ListBuilder& ListBuilder::SetLaserDelays(double on_us, double off_us) {
  // Laser-on delays may be negative on RTC boards (laser on before the move); off may not.
  std::string problem = std::isfinite(on_us) ? "" : "laser-on delay is not a number";
  if (problem.empty()) problem = NonNegativeProblem(off_us, "laser-off delay");
  return Add({ListOp::kSetLaserDelays, {}, on_us, off_us}, problem);
}

ListBuilder& ListBuilder::SetScannerDelays(double jump_us, double mark_us, double polygon_us) {
  std::string problem = NonNegativeProblem(jump_us, "jump delay");
  if (problem.empty()) problem = NonNegativeProblem(mark_us, "mark delay");
  if (problem.empty()) problem = NonNegativeProblem(polygon_us, "polygon delay");
  return Add({ListOp::kSetScannerDelays, {}, jump_us, mark_us, polygon_us}, problem);
}

ListBuilder& ListBuilder::SetLaserPower(double fraction) {
  return Add({ListOp::kSetLaserPower, {}, fraction},
             std::isfinite(fraction) && fraction >= 0 && fraction <= 1
                 ? ""
                 : "laser power must be a fraction in [0, 1]");
}

ListBuilder& ListBuilder::SetLaserFrequency(double khz) {
  return Add({ListOp::kSetLaserFrequency, {}, khz}, PositiveProblem(khz, "laser frequency"));
}

Result<std::vector<ListCommand>> ListBuilder::Finish() {
  if (!error_.ok()) return error_;
  if (commands_.empty()) return InvalidArgument("the list is empty");
  std::vector<ListCommand> out = commands_;
  out.push_back({ListOp::kEndOfList});
  return out;
}

Status HeadFormat::Validate() const {
  if (bits != 16 && bits != 20) {
    return InvalidArgument("bits must be 16 (XY2-100) or 20 (SL2-100), got " +
                           std::to_string(bits));
  }
  if (!(field_half_size_mm > 0)) return InvalidArgument("field_half_size_mm must be > 0");
  if (!(focus_half_range_mm > 0)) return InvalidArgument("focus_half_range_mm must be > 0");
  if (!(clock_us > 0)) return InvalidArgument("clock_us must be > 0");
  return Status::Ok();
}

Result<std::vector<EmittedCommand>> Emit(const std::vector<ListCommand>& list,
                                         const HeadFormat& f, const FieldCorrection& correction) {
  INSITU_RETURN_IF_ERROR(f.Validate());
  if (list.empty() || list.back().op != ListOp::kEndOfList) {
    return InvalidArgument("the list does not end with set_end_of_list");
  }
  std::vector<EmittedCommand> out;
  out.reserve(list.size());
  auto ticks = [&](double us) { return static_cast<int64_t>(std::llround(us / f.clock_us)); };
  for (size_t i = 0; i < list.size(); ++i) {
    const ListCommand& c = list[i];
    EmittedCommand e;
    e.op = c.op;
    switch (c.op) {
      case ListOp::kJumpAbs:
      case ListOp::kMarkAbs: {
        const Eigen::Vector3d sent = correction ? correction(c.p) : c.p;
        char where[200];
        std::snprintf(where, sizeof where, "list command %zu (%s) to (%.3f, %.3f, %.3f) mm", i,
                      ListOpName(c.op), c.p.x(), c.p.y(), c.p.z());
        if (!sent.allFinite()) {
          return OutOfRange(std::string(where) + ": the field correction has no value there");
        }
        char corrected[120] = "";
        if (correction) {
          std::snprintf(corrected, sizeof corrected, " (corrected (%.3f, %.3f, %.3f) mm)",
                        sent.x(), sent.y(), sent.z());
        }
        if (std::abs(sent.x()) > f.field_half_size_mm ||
            std::abs(sent.y()) > f.field_half_size_mm) {
          char limit[80];
          std::snprintf(limit, sizeof limit, " leaves the field +-%.3f mm", f.field_half_size_mm);
          return OutOfRange(std::string(where) + corrected + limit);
        }
        if (std::abs(sent.z()) > f.focus_half_range_mm) {
          char limit[80];
          std::snprintf(limit, sizeof limit, " leaves the focus range +-%.3f mm",
                        f.focus_half_range_mm);
          return OutOfRange(std::string(where) + corrected + limit);
        }
        e.x = std::llround(sent.x() * f.counts_per_mm());
        e.y = std::llround(sent.y() * f.counts_per_mm());
        e.z = std::llround(sent.z() * f.z_counts_per_mm());
        break;
      }
      case ListOp::kSetJumpSpeed:
      case ListOp::kSetMarkSpeed:
        e.a = std::llround(c.a * 1e-3 * f.counts_per_mm());  // bits per ms
        break;
      case ListOp::kSetLaserDelays:
        e.a = ticks(c.a);
        e.b = ticks(c.b);
        break;
      case ListOp::kSetScannerDelays:
        e.a = ticks(c.a);
        e.b = ticks(c.b);
        e.c = ticks(c.c);
        break;
      case ListOp::kSetLaserPower:
        e.a = std::llround(c.a * 65535.0);
        break;
      case ListOp::kSetLaserFrequency:
        e.a = std::llround(c.a * 1e3);
        break;
      case ListOp::kEndOfList:
        if (i + 1 != list.size()) {
          return InvalidArgument("list command " + std::to_string(i) +
                                 ": set_end_of_list before the end");
        }
        break;
    }
    out.push_back(e);
  }
  return out;
}

std::string FormatEmitted(const std::vector<EmittedCommand>& list, const HeadFormat& f) {
  std::ostringstream os;
  os << "# insitu galvo list: " << f.bits << "-bit head, field +-" << f.field_half_size_mm
     << " mm = +-" << f.max_count() << " counts, focus +-" << f.focus_half_range_mm
     << " mm, clock " << f.clock_us << " us\n";
  for (const EmittedCommand& e : list) {
    os << ListOpName(e.op);
    switch (e.op) {
      case ListOp::kJumpAbs:
      case ListOp::kMarkAbs: os << ' ' << e.x << ' ' << e.y << ' ' << e.z; break;
      case ListOp::kSetJumpSpeed:
      case ListOp::kSetMarkSpeed:
      case ListOp::kSetLaserPower:
      case ListOp::kSetLaserFrequency: os << ' ' << e.a; break;
      case ListOp::kSetLaserDelays: os << ' ' << e.a << ' ' << e.b; break;
      case ListOp::kSetScannerDelays: os << ' ' << e.a << ' ' << e.b << ' ' << e.c; break;
      case ListOp::kEndOfList: break;
    }
    os << '\n';
  }
  return os.str();
}

double ListDuration(const std::vector<ListCommand>& list) {
  double t = 0.0, jump = 0.0, mark = 0.0, jump_delay = 0.0, mark_delay = 0.0;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  for (const ListCommand& c : list) {
    switch (c.op) {
      case ListOp::kSetJumpSpeed: jump = c.a; break;
      case ListOp::kSetMarkSpeed: mark = c.a; break;
      case ListOp::kSetScannerDelays:
        jump_delay = c.a * 1e-6;
        mark_delay = c.b * 1e-6;
        break;
      case ListOp::kJumpAbs:
        if (jump > 0) t += (c.p - at).head<2>().norm() / jump;
        t += jump_delay;
        at = c.p;
        break;
      case ListOp::kMarkAbs:
        if (mark > 0) t += (c.p - at).head<2>().norm() / mark;
        t += mark_delay;
        at = c.p;
        break;
      default: break;
    }
  }
  return t;
}

}  // namespace insitu::pattern
