// The scanned point cloud: points in the galvo (= world) frame, mm, with where each came from.
// Stored as plain structs; PCL is used behind SaveCloudPly only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::geometry {

struct CloudPoint {
  Eigen::Vector3f point_in_galvo;  // mm
  float intensity = 0.0f;          // stripe peak above the local background, gray levels
  int32_t line = 0;                // scan line index
  float pixel_u = 0.0f;            // stripe centre in the frame
  float pixel_v = 0.0f;
  // The centre's standard uncertainty across the stripe (pixels) from the local noise: the
  // scan's confidence in the point (vision::StripeResult::sigma_px).
  float center_sigma_px = 0.0f;
};

using Cloud = std::vector<CloudPoint>;

// Binary PLY (x, y, z, intensity, sigma_px: the centre's uncertainty) through
// pcl::io::savePLYFile. Errors: device_error naming the
// path.
Status SaveCloudPly(const Cloud& cloud, const std::string& path);

}  // namespace insitu::geometry
