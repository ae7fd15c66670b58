// The insert's picture for the scan job's report (internal to the job module); the measurement
// itself is inspect::EvaluateInsert.
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/geometry/cloud.h"
#include "insitu/inspect/insert.h"

namespace insitu::job {

// Top view of the insert for the report (insert.png): the scanned top shaded by height, the
// outline and hole edge points, the fitted edges and circle, and the measured dimensions.
// Errors: device_error if the file cannot be written.
Status SaveInsertPicture(const geometry::Cloud& cloud, const inspect::InsertResult& result,
                         const inspect::InsertSpec& spec, const std::string& path);

}  // namespace insitu::job
