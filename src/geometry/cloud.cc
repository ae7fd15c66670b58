#include "insitu/geometry/cloud.h"

#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

namespace insitu::geometry {
// A cloud point as the PLY file holds it: PCL's x, y, z, intensity and the centre's uncertainty.
struct PlyPoint {
  PCL_ADD_POINT4D;
  float intensity;
  float sigma_px;
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};
}  // namespace insitu::geometry

POINT_CLOUD_REGISTER_POINT_STRUCT(
    insitu::geometry::PlyPoint,
    (float, x, x)(float, y, y)(float, z, z)(float, intensity, intensity)(float, sigma_px, sigma_px))

namespace insitu::geometry {

Status SaveCloudPly(const Cloud& cloud, const std::string& path) {
  pcl::PointCloud<PlyPoint> pc;
  pc.reserve(cloud.size());
  for (const CloudPoint& p : cloud) {
    PlyPoint q;
    q.x = p.point_in_galvo.x();
    q.y = p.point_in_galvo.y();
    q.z = p.point_in_galvo.z();
    q.intensity = p.intensity;
    q.sigma_px = p.center_sigma_px;
    pc.push_back(q);
  }
  pc.width = static_cast<uint32_t>(pc.size());
  pc.height = 1;
  try {
    if (pc.empty()) return InvalidArgument("refusing to write an empty cloud to " + path);
    if (pcl::io::savePLYFileBinary(path, pc) != 0) {
      return DeviceError("cannot write point cloud " + path);
    }
  } catch (const std::exception& e) {
    return DeviceError("cannot write point cloud " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace insitu::geometry
