#include "job/head_list.h"

#include <algorithm>
#include <cmath>

namespace insitu::job {

hw::GalvoList ToHeadList(const std::vector<pattern::ListCommand>& list,
                         const pattern::FieldCorrection& correction) {
  hw::GalvoList out;
  const auto corrected = [&](const Eigen::Vector3d& p) { return correction ? correction(p) : p; };
  for (const pattern::ListCommand& c : list) {
    switch (c.op) {
      case pattern::ListOp::kJumpAbs:
        out.entries.push_back({hw::GalvoListEntry::Kind::kJump, corrected(c.p)});
        break;
      case pattern::ListOp::kMarkAbs:
        out.entries.push_back({hw::GalvoListEntry::Kind::kMark, corrected(c.p)});
        break;
      case pattern::ListOp::kSetJumpSpeed:
        out.jump_speed_mm_per_s = c.a;
        break;
      case pattern::ListOp::kSetMarkSpeed:
        out.mark_speed_mm_per_s = c.a;
        break;
      case pattern::ListOp::kSetLaserDelays:
        out.laser_on_delay_us = std::max(0.0, c.a);
        out.laser_off_delay_us = c.b;
        break;
      case pattern::ListOp::kSetScannerDelays:
        out.jump_delay_us = c.a;
        out.mark_delay_us = c.b;
        break;
      case pattern::ListOp::kSetLaserPower:
        out.laser_power = c.a;
        break;
      case pattern::ListOp::kSetLaserFrequency:
        out.laser_frequency_khz = c.a;
        break;
      case pattern::ListOp::kEndOfList:
        break;
    }
  }
  return out;
}

pattern::FieldCorrection MeasuredHeadCorrection(const calib::CalibrationSet& calibration) {
  if (!calibration.head.measured) return {};
  return [head = calibration.head](const Eigen::Vector3d& p) {
    Eigen::Vector3d c;
    return head.MarkCommandFor(p, &c) ? c : Eigen::Vector3d::Constant(NAN);
  };
}

}  // namespace insitu::job
