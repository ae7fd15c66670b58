#include "insitu/geometry/triangulation.h"

#include <gtest/gtest.h>

namespace insitu::geometry {
namespace {

Eigen::Isometry3d SideCamera() {
  // Camera 350 mm away, looking down at the origin from the -x side (as mounted on the cell).
  const Eigen::Vector3d c(-180, 0, 300);
  const Eigen::Vector3d z = (-c).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Isometry3d galvo_from_camera = Eigen::Isometry3d::Identity();
  galvo_from_camera.linear() << x, y, z;
  galvo_from_camera.translation() = c;
  return galvo_from_camera.inverse();
}

// A point on the light plane through a, b, c, seen by the camera, comes back exactly
// (eq. 1-4 are exact for a plane): error at the 1e-9 mm level.
TEST(Triangulation, PointOnThePlaneRoundTrips) {
  const Eigen::Isometry3d camera_from_galvo = SideCamera();
  const Eigen::Vector3d a(0, 0, 355), b(8, -50, 0), c(8, 50, 0);
  const PlaneInCamera plane = LightPlaneInCamera(a, b, c, camera_from_galvo);
  // A point 12 mm up on the plane, 20 mm along the line.
  const double t = 12.0 / 355.0;
  const Eigen::Vector3d on_line(8, 20, 0);
  const Eigen::Vector3d p = on_line + t * (a - on_line);
  const Eigen::Vector3d pc = camera_from_galvo * p;
  const auto hit = IntersectRayWithPlane(pc.head<2>() / pc.z(), plane);
  ASSERT_TRUE(hit.has_value());
  const Eigen::Vector3d back = camera_from_galvo.inverse() * *hit;
  EXPECT_NEAR((back - p).norm(), 0.0, 1e-9);
}

TEST(Triangulation, TelecentricPlaneIsVertical) {
  calib::GalvoGeometry g;
  g.lens = calib::ScanLens::kTelecentric;
  const Eigen::Vector3d a = PivotPoint(g, {8, -50, 0});
  EXPECT_DOUBLE_EQ(a.x(), 8.0);
  g.lens = calib::ScanLens::kFTheta;
  EXPECT_DOUBLE_EQ(PivotPoint(g, {8, -50, 0}).x(), 0.0);
}

TEST(Triangulation, RayParallelToPlaneGivesNothing) {
  PlaneInCamera plane;
  plane.coeffs << 0, 0, 1, -100;  // z = 100
  EXPECT_TRUE(IntersectRayWithPlane({0.1, 0.2}, plane).has_value());
  plane.coeffs << 1, 0, 0, -5;    // x = 5, ray (0, 0, 1) never meets it
  EXPECT_FALSE(IntersectRayWithPlane({0.0, 0.0}, plane).has_value());
  plane.coeffs << 0, 0, 1, 100;   // z = -100: behind the camera
  EXPECT_FALSE(IntersectRayWithPlane({0.0, 0.0}, plane).has_value());
}

}  // namespace
}  // namespace insitu::geometry
