// A finished galvo list as the scan head takes it, and the arming around it: what every job
// that marks shares. Internal to the job module.
#pragma once

#include <vector>

#include "insitu/calib/calibration.h"
#include "insitu/hw/scanner.h"
#include "insitu/pattern/galvo_list.h"

namespace insitu::job {

// The list's moves (field-corrected, as Emit sends them) and settings for the scan head.
hw::GalvoList ToHeadList(const std::vector<pattern::ListCommand>& list,
                         const pattern::FieldCorrection& correction);

// The head the field calibration measured (calibration.head.measured): every point is sent
// as the command that puts the marking beam on it; where no command does (the inverse does
// not converge) the point becomes NaN, which Emit refuses by name, so it is never marked
// uncorrected. Empty when the calibration measured no head.
pattern::FieldCorrection MeasuredHeadCorrection(const calib::CalibrationSet& calibration);

// Disarms on every way out of the marking step.
struct ArmGuard {
  hw::Scanner* scanner;
  ~ArmGuard() { (void)scanner->Disarm(); }
};

}  // namespace insitu::job
