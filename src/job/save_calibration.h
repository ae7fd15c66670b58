// Writing a measured calibration set as the calibration jobs do: a copy beside the report
// first, so what was measured survives a configured file that cannot be written, then the
// configured file, atomically. The previous calibration stays in effect on any failure.
#pragma once

#include <filesystem>
#include <string>

#include "insitu/calib/calibration.h"
#include "insitu/job/report.h"

namespace insitu::job {

// Adds artifacts `calibration_copy` and `calibration` to the report. The error names where
// the measured calibration still is.
inline Status SaveMeasuredCalibration(const calib::CalibrationSet& set, const std::string& output,
                                      const std::string& out_dir, Report* report) {
  const std::string copy = (std::filesystem::path(out_dir) / "calibration.yaml").string();
  const Status copied = calib::SaveCalibration(set, copy);
  if (copied.ok()) report->artifacts["calibration_copy"] = "calibration.yaml";
  const Status saved = calib::SaveCalibration(set, output);
  if (!saved.ok()) {
    return Status(saved.code(), saved.message() +
                                    (copied.ok() ? "; the measured calibration is in " + copy : ""));
  }
  std::error_code ec;
  const std::filesystem::path rel = std::filesystem::relative(output, out_dir, ec);
  report->artifacts["calibration"] = ec ? output : rel.string();
  return Status::Ok();
}

}  // namespace insitu::job
