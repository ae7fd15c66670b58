// `insitu diagnose DATA.csv [--out DIR]`: loads measured galvo field data (CONTRACT.md), runs
// fit::Diagnose, and writes DIR/report.json (the diagnose schema of CONTRACT.md),
// DIR/residuals.png (the residual vector field before and after, arrows scaled and labelled)
// and DIR/extension.yaml (the extended model: fit/extension.h).
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/fit/diagnose.h"

namespace insitu::job {

// Errors: those of loading the data (file, line, column named) and of the diagnosis; an output
// folder that cannot be made or written (not_found / device_error naming it).
Result<fit::Diagnosis> RunDiagnose(const std::string& csv_path, const std::string& out_dir,
                                   const fit::DiagnoseOptions& options = {});

}  // namespace insitu::job
