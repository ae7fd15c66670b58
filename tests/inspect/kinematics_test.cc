// The profiler's kinematic chain (seed 002 eq. 1-10): the mounting's Euler angles round-trip,
// the tool's rotation is one, and the mounting is calibrated from a block's points to what the
// sensor's and the CMM's noise allow.
#include "insitu/inspect/kinematics.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

namespace insitu::inspect {
namespace {

using Eigen::Vector3d;

TEST(Kinematics, EulerAnglesRoundTrip) {
  SensorMount m;
  m.theta_rad = 0.3;
  m.psi_rad = -0.7;
  m.phi_rad = 2.1;
  const Eigen::Matrix3d r = m.Rotation();
  EXPECT_NEAR(r(2, 0), -std::sin(m.theta_rad), 1e-12);  // eq. 8's third row
  EXPECT_NEAR(r(2, 1), std::sin(m.psi_rad) * std::cos(m.theta_rad), 1e-12);
  const SensorMount back = SensorMount::FromRotation(r, Vector3d(1, 2, 3));
  EXPECT_NEAR(back.theta_rad, m.theta_rad, 1e-12);
  EXPECT_NEAR(back.psi_rad, m.psi_rad, 1e-12);
  EXPECT_NEAR(back.phi_rad, m.phi_rad, 1e-12);
}

TEST(Kinematics, TheToolsRotationIsARotation) {
  const ToolPose t{Vector3d(1, 2, 3), 0.4, -1.1};
  const Eigen::Matrix3d r = t.Rotation();
  EXPECT_NEAR((r * r.transpose() - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-12);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  // A turn of C alone turns about z.
  const ToolPose c{Vector3d::Zero(), 0.0, M_PI / 2};
  EXPECT_TRUE((c.Rotation() * Vector3d::UnitX()).isApprox(Vector3d::UnitY(), 1e-12));
}

// A profiler mounted 150 mm below the tool, turned ~1.2 rad about z and tilted by tens of mrad,
// sees a calibration block from three tool positions: 40 points along each of 3 profiles, 2 um
// range noise, the block's points known to 3 um (a CMM). Over 40 mm of line the angles are
// known to ~(3 um / 20 mm) / sqrt(120): 1.5e-5 rad; the bounds are ~10 of that.
TEST(Kinematics, TheMountingIsCalibratedFromABlock) {
  SensorMount truth;
  truth.theta_rad = 0.02;
  truth.psi_rad = -0.03;
  truth.phi_rad = 1.2;
  truth.translation_mm = Vector3d(10.0, -5.0, -150.0);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> range(0.0, 0.002), cmm(0.0, 0.003);
  std::uniform_real_distribution<double> height(95.0, 105.0);
  std::vector<MountObservation> obs;
  for (double y : {0.0, 20.0, 40.0}) {
    const ToolPose tool{Vector3d(100.0, y, 300.0), 0.0, 0.0};
    for (int i = 0; i < 40; ++i) {
      const Vector3d s = SensorPoint(-20.0 + i, height(rng));
      const Vector3d w = ToWorkpiece(tool, truth, s);
      obs.push_back({s + Vector3d(0, 0, range(rng)), tool.position_mm,
                     w + Vector3d(cmm(rng), cmm(rng), cmm(rng))});
    }
  }
  auto cal = CalibrateMount(obs);
  ASSERT_TRUE(cal.ok()) << cal.status().ToString();
  std::printf(
      "mount: theta %+.2e psi %+.2e phi %+.2e rad off, translation %.1f um off, rms %.1f um\n",
      cal->mount.theta_rad - truth.theta_rad, cal->mount.psi_rad - truth.psi_rad,
      cal->mount.phi_rad - truth.phi_rad,
      1e3 * (cal->mount.translation_mm - truth.translation_mm).norm(), 1e3 * cal->rms_mm);
  EXPECT_NEAR(cal->mount.theta_rad, truth.theta_rad, 2e-4);
  EXPECT_NEAR(cal->mount.psi_rad, truth.psi_rad, 2e-4);
  EXPECT_NEAR(cal->mount.phi_rad, truth.phi_rad, 2e-4);
  EXPECT_LT((cal->mount.translation_mm - truth.translation_mm).norm(), 0.02);
  // The residual: the CMM's 3 um per axis and the range's 2 um, ~5.6 um as a vector.
  EXPECT_GT(cal->rms_mm, 0.003);
  EXPECT_LT(cal->rms_mm, 0.008);
}

TEST(Kinematics, TooFewOrCollinearPointsAreRefused) {
  std::vector<MountObservation> obs;
  for (int i = 0; i < 5; ++i) {
    obs.push_back({SensorPoint(i, 100.0), Vector3d::Zero(), Vector3d(i, 0, 100.0)});
  }
  auto line = CalibrateMount(obs);
  ASSERT_FALSE(line.ok());
  EXPECT_NE(line.status().message().find("one line"), std::string::npos);
  obs.resize(2);
  EXPECT_FALSE(CalibrateMount(obs).ok());
}

}  // namespace
}  // namespace insitu::inspect
