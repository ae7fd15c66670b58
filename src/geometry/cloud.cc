#include "insitu/geometry/cloud.h"

#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

namespace insitu::geometry {

Status SaveCloudPly(const Cloud& cloud, const std::string& path) {
  pcl::PointCloud<pcl::PointXYZI> pc;
  pc.reserve(cloud.size());
  for (const CloudPoint& p : cloud) {
    pcl::PointXYZI q;
    q.x = p.point_in_galvo.x();
    q.y = p.point_in_galvo.y();
    q.z = p.point_in_galvo.z();
    q.intensity = p.intensity;
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
