// `insitu diagnose DATA [--out DIR]`: loads galvo field data (LoadDiagnoseData), runs
// fit::Diagnose, and writes DIR/report.json (the diagnose schema of CONTRACT.md),
// DIR/residuals.png (the residual vector field before and after, arrows scaled and labelled)
// and DIR/extension.yaml (the extended model: fit/extension.h).
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/fit/diagnose.h"

namespace insitu::job {

// The data a diagnosis reads, by what the file is: an EzCad .cor table (read the way the head
// model explains it: job/cor_reading.h), a correction table CSV (x_mm, y_mm, dx_mm, dy_mm: what
// `insitu cor import` and field_calibration write), or measured field data (CONTRACT.md; what
// field_calibration's field.csv holds). A table becomes the head without it: commanded p +
// offset, landing on p. `source` says which, and for a .cor which reading. Errors: the
// loader's (file, line, column named). `cor_reading` forces the reading of a .cor file
// (hw::lmc::ParseCorReading's code; empty: the evidence decides, job/cor_reading.h).
Result<fit::FieldData> LoadDiagnoseData(const std::string& path, std::string* source,
                                        const std::string& cor_reading = "");

// Errors: those of loading the data (file, line, column named) and of the diagnosis; an output
// folder that cannot be made or written (not_found / device_error naming it).
Result<fit::Diagnosis> RunDiagnose(const std::string& csv_path, const std::string& out_dir,
                                   const fit::DiagnoseOptions& options = {},
                                   const std::string& cor_reading = "");

}  // namespace insitu::job
