#include "insitu/optics/scan_head.h"

#include <cmath>

#include <gtest/gtest.h>

namespace insitu::optics {
namespace {

// The reflection trace with axes as designed is the closed form of the two-mirror head:
// d = (sin a, cos a sin b, -cos a cos b), r = f theta along d's azimuth.
TEST(ScanOptics, ReflectionsReduceToTheClosedForm) {
  const HeadGeometry g;
  const ScanOptics optics{g};
  for (double a : {-0.2, -0.05, 0.0, 0.11}) {
    for (double b : {-0.17, 0.0, 0.03, 0.2}) {
      const Eigen::Vector3d d(std::sin(a), std::cos(a) * std::sin(b), -std::cos(a) * std::cos(b));
      const double sin_t = std::hypot(d.x(), d.y());
      const double theta = std::atan2(sin_t, -d.z());
      const double scale = sin_t > 0 ? g.focal_length_mm * theta / sin_t : g.focal_length_mm;
      const Eigen::Vector3d f = optics.Trace({a, b}).focal_point_in_world;
      EXPECT_NEAR(f.x(), scale * d.x(), 1e-9) << a << " " << b;
      EXPECT_NEAR(f.y(), scale * d.y(), 1e-9) << a << " " << b;
    }
  }
}

// f-theta distortion scales the image height by 1 + c3 theta^2 + c5 theta^4 and nothing else.
TEST(ScanOptics, FThetaDistortionScalesTheImageHeight) {
  HeadGeometry g;
  const Eigen::Vector3d plain = ScanOptics{g}.Trace({0.12, 0.09}).focal_point_in_world;
  g.ftheta_c3 = 0.05;
  g.ftheta_c5 = -0.3;
  const Eigen::Vector3d bent = ScanOptics{g}.Trace({0.12, 0.09}).focal_point_in_world;
  const double theta = plain.norm() / 255.0;
  const double t2 = theta * theta;
  EXPECT_NEAR(bent.norm() / plain.norm(), 1 + 0.05 * t2 - 0.3 * t2 * t2, 1e-12);
  EXPECT_NEAR(std::atan2(bent.y(), bent.x()), std::atan2(plain.y(), plain.x()), 1e-12);
}

// A tilted axis changes nothing at the mirror's zero. Away from it the X mirror, rotating about
// an axis leaned by tau toward its incoming beam, lifts the beam out of its plane by ~tau
// sin(a/2): after the Y mirror a line scanned along x leans in y by ~f tau a / 2 (the axes are
// no longer orthogonal, a shear), with the odd symmetry of a shear.
TEST(ScanOptics, TiltedMirrorAxisShearsTheField) {
  HeadGeometry g;
  const ScanOptics straight{g};
  g.x_axis_tilt_mrad = 2.0;
  const ScanOptics tilted{g};
  EXPECT_NEAR((tilted.Trace({0.0, 0.05}).focal_point_in_world -
               straight.Trace({0.0, 0.05}).focal_point_in_world).norm(), 0.0, 1e-12);
  const double a = 0.2;
  const double lean = tilted.Trace({a, 0.0}).focal_point_in_world.y() -
                      straight.Trace({a, 0.0}).focal_point_in_world.y();
  const double lean_neg = tilted.Trace({-a, 0.0}).focal_point_in_world.y() -
                          straight.Trace({-a, 0.0}).focal_point_in_world.y();
  // Odd part: the shear, within 10 % (higher orders); even part: a second-order bow, smaller.
  const double odd = 0.5 * (lean - lean_neg), even = 0.5 * (lean + lean_neg);
  EXPECT_NEAR(odd, 255.0 * 2e-3 * a / 2, 0.1 * 255.0 * 2e-3 * a / 2);
  EXPECT_LT(std::abs(even), 0.1 * std::abs(odd));
  // The Y mirror's tilt shears the other way: x moves with b.
  HeadGeometry gy;
  gy.y_axis_tilt_mrad = 2.0;
  const double lean_y = ScanOptics{gy}.Trace({0.0, a}).focal_point_in_world.x() -
                        straight.Trace({0.0, a}).focal_point_in_world.x();
  EXPECT_NEAR(std::abs(lean_y), 255.0 * 2e-3 * a / 2, 0.1 * 255.0 * 2e-3 * a / 2);
}

// A beam entering misaligned by (ox, oy) mrad lands about f (ox, oy) away; lateral colour
// scales the image height.
TEST(ScanOptics, BeamPathOffsetAndLateralColour) {
  const ScanOptics optics{HeadGeometry{}};
  BeamPath pointer;
  pointer.offset_x_mrad = 0.2;
  pointer.offset_y_mrad = -0.1;
  const Eigen::Vector3d c = optics.Trace({0, 0}, pointer).focal_point_in_world;
  EXPECT_NEAR(c.x(), 255.0 * 0.2e-3, 1e-4);
  EXPECT_NEAR(c.y(), -255.0 * 0.1e-3, 1e-4);
  BeamPath colour;
  colour.lateral_colour_pct = -0.4;
  const Eigen::Vector3d p = optics.Trace({0.1, -0.07}).focal_point_in_world;
  const Eigen::Vector3d q = optics.Trace({0.1, -0.07}, colour).focal_point_in_world;
  EXPECT_NEAR(q.x() / p.x(), 0.996, 1e-12);
  EXPECT_NEAR(q.y() / p.y(), 0.996, 1e-12);
}

// A head whose build differs from its design lands off the command; CommandFor finds the
// command that lands on target, to the Newton tolerance.
TEST(HeadModel, CommandForInvertsLanding) {
  HeadModel head;
  EXPECT_TRUE(head.Validate().ok());
  Eigen::Vector3d spot;
  ASSERT_TRUE(head.Spot({30.0, -40.0, 5.0}, {}, &spot));
  EXPECT_NEAR((spot - Eigen::Vector3d(30.0, -40.0, 5.0)).norm(), 0.0, 1e-8);  // as designed
  head.built.focal_length_mm = 256.2;
  head.built.ftheta_c3 = 0.04;
  head.built.x_axis_tilt_mrad = 1.0;
  head.x_zero_offset_mrad = 0.3;
  ASSERT_TRUE(head.Spot({60.0, 50.0, 0.0}, {}, &spot));
  EXPECT_GT((spot - Eigen::Vector3d(60.0, 50.0, 0.0)).norm(), 0.2);  // 0.47 % of 78 mm, and more
  for (const Eigen::Vector3d& target : {Eigen::Vector3d(60, 50, 0), Eigen::Vector3d(-65, 10, -8),
                                       Eigen::Vector3d(0, 0, 12)}) {
    Eigen::Vector3d cmd;
    ASSERT_TRUE(head.CommandFor(target, {}, &cmd));
    ASSERT_TRUE(head.Spot(cmd, {}, &spot));
    EXPECT_NEAR((spot - target).norm(), 0.0, 1e-6);
    EXPECT_EQ(cmd.z(), target.z());
  }
  head.built.ftheta_c3 = 5.0;
  EXPECT_FALSE(head.Validate().ok());
}

TEST(ScanOptics, OnAxisBeamHitsTheFieldCentreVertically) {
  ScanOptics optics{HeadGeometry{}};
  const ChiefRay ray = optics.Trace({0.0, 0.0});
  EXPECT_NEAR(ray.focal_point_in_world.norm(), 0.0, 1e-12);
  EXPECT_NEAR(ray.up.z(), 1.0, 1e-12);
}

// f-theta: along each axis alone the image height is exactly f * angle.
TEST(ScanOptics, FThetaAlongTheAxes) {
  ScanOptics optics{HeadGeometry{}};
  EXPECT_NEAR(optics.Trace({0.1, 0.0}).focal_point_in_world.x(), 25.5, 1e-9);
  EXPECT_NEAR(optics.Trace({0.0, -0.1}).focal_point_in_world.y(), -25.5, 1e-9);
}

// Two-mirror geometry (seed 003): a line of constant X-mirror angle bows outward in x as the
// Y mirror turns (pincushion); a line of constant Y angle bows inward in y (barrel).
TEST(ScanOptics, TwoMirrorFieldIsPincushionInXAndBarrelInY) {
  ScanOptics optics{HeadGeometry{}};
  const double x_centre = optics.Trace({0.08, 0.0}).focal_point_in_world.x();
  const double x_edge = optics.Trace({0.08, 0.16}).focal_point_in_world.x();
  EXPECT_GT(x_edge - x_centre, 0.03);  // ~0.07 mm at 40 mm off axis, f = 255 mm
  const double y_centre = optics.Trace({0.0, 0.08}).focal_point_in_world.y();
  const double y_edge = optics.Trace({0.16, 0.08}).focal_point_in_world.y();
  EXPECT_LT(y_edge - y_centre, -0.03);
}

TEST(ScanOptics, SolveInvertsTraceAtAnyHeight) {
  ScanOptics optics{HeadGeometry{}};
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
  HeadGeometry g;
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
  ScanOptics optics{HeadGeometry{}};
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
}  // namespace insitu::optics
