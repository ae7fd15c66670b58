#include "insitu/sim/scan_optics.h"

#include <cmath>

#include <gtest/gtest.h>

namespace insitu::sim {
namespace {

TEST(ScanOptics, OnAxisBeamHitsTheFieldCentreVertically) {
  ScanOptics optics{ScanOpticsGeometry{}};
  const ChiefRay ray = optics.Trace({0.0, 0.0});
  EXPECT_NEAR(ray.focal_point_in_world.norm(), 0.0, 1e-12);
  EXPECT_NEAR(ray.up.z(), 1.0, 1e-12);
}

// f-theta: along each axis alone the image height is exactly f * angle.
TEST(ScanOptics, FThetaAlongTheAxes) {
  ScanOptics optics{ScanOpticsGeometry{}};
  EXPECT_NEAR(optics.Trace({0.1, 0.0}).focal_point_in_world.x(), 25.5, 1e-9);
  EXPECT_NEAR(optics.Trace({0.0, -0.1}).focal_point_in_world.y(), -25.5, 1e-9);
}

// Two-mirror geometry (seed 003): a line of constant X-mirror angle bows outward in x as the
// Y mirror turns (pincushion); a line of constant Y angle bows inward in y (barrel).
TEST(ScanOptics, TwoMirrorFieldIsPincushionInXAndBarrelInY) {
  ScanOptics optics{ScanOpticsGeometry{}};
  const double x_centre = optics.Trace({0.08, 0.0}).focal_point_in_world.x();
  const double x_edge = optics.Trace({0.08, 0.16}).focal_point_in_world.x();
  EXPECT_GT(x_edge - x_centre, 0.03);  // ~0.07 mm at 40 mm off axis, f = 255 mm
  const double y_centre = optics.Trace({0.0, 0.08}).focal_point_in_world.y();
  const double y_edge = optics.Trace({0.16, 0.08}).focal_point_in_world.y();
  EXPECT_LT(y_edge - y_centre, -0.03);
}

TEST(ScanOptics, SolveInvertsTraceAtAnyHeight) {
  ScanOptics optics{ScanOpticsGeometry{}};
  for (double z : {-10.0, 0.0, 15.0}) {
    for (double x : {-50.0, 0.0, 33.0}) {
      for (double y : {-60.0, 5.0, 60.0}) {
        MirrorAngles a;
        ASSERT_TRUE(optics.Solve(x, y, z, &a));
        const Eigen::Vector3d p = optics.Trace(a).AtHeight(z);
        EXPECT_NEAR(p.x(), x, 1e-7);
        EXPECT_NEAR(p.y(), y, 1e-7);
      }
    }
  }
}

// Non-telecentric: chief rays come from the exit pupil, which the X deflection shifts by
// e tan(a) L / f and whose height falls to L / (1 + pa (theta / 0.2)^2) off axis; a point
// 15 mm up lands (x0 - shift) * 15 / L_eff closer to the axis. Telecentric rays stand vertical.
TEST(ScanOptics, ChiefRaysLeanOutwardUnlessTelecentric) {
  ScanOpticsGeometry g;
  ScanOptics optics{g};
  const ChiefRay ray = optics.Trace({0.1, 0.0});
  const double x0 = ray.focal_point_in_world.x();
  const double shift = g.mirror_separation_mm * std::tan(0.1) * g.exit_pupil_height_mm /
                       g.focal_length_mm;
  const double l_eff = g.exit_pupil_height_mm / (1.0 + g.pupil_aberration * 0.25);
  EXPECT_NEAR(x0 - ray.AtHeight(15.0).x(), (x0 - shift) * 15.0 / l_eff, 1e-6);
  g.telecentric = true;
  const ChiefRay tele = ScanOptics{g}.Trace({0.1, 0.0});
  EXPECT_NEAR(tele.AtHeight(15.0).x(), tele.focal_point_in_world.x(), 1e-12);
}

// The beams of one scan line (fixed X command) do not lie in one plane: the pupil aberration
// and the X mirror's offset bend the sheet. Measured: deviation of the mid-line ray at 15 mm
// height from the plane through the pupil apex and the line's two end rays.
TEST(ScanOptics, ScanLineSweepsACurvedSheet) {
  ScanOptics optics{ScanOpticsGeometry{}};
  MirrorAngles a0, a1, am;
  ASSERT_TRUE(optics.Solve(20.0, -40.0, 0.0, &a0));
  ASSERT_TRUE(optics.Solve(20.0, 40.0, 0.0, &a1));
  ASSERT_TRUE(optics.Solve(20.0, 0.0, 0.0, &am));
  const Eigen::Vector3d p0 = optics.Trace(a0).AtHeight(15.0);
  const Eigen::Vector3d p1 = optics.Trace(a1).AtHeight(15.0);
  const Eigen::Vector3d pm = optics.Trace(am).AtHeight(15.0);
  // On a plane containing the focal-plane line x = 20, points at equal height share x.
  EXPECT_GT(std::abs(pm.x() - 0.5 * (p0.x() + p1.x())), 1e-3);
}

}  // namespace
}  // namespace insitu::sim
