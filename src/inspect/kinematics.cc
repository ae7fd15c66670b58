#include "insitu/inspect/kinematics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace insitu::inspect {

Eigen::Matrix3d SensorMount::Rotation() const {
  return (Eigen::AngleAxisd(phi_rad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(theta_rad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(psi_rad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

SensorMount SensorMount::FromRotation(const Eigen::Matrix3d& r, const Eigen::Vector3d& t) {
  // Eq. 8: r(2,0) = -sin theta, r(2,1) = sin psi cos theta, r(2,2) = cos psi cos theta,
  // r(0,0) = cos theta cos phi, r(1,0) = cos theta sin phi.
  SensorMount m;
  m.theta_rad = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  m.psi_rad = std::atan2(r(2, 1), r(2, 2));
  m.phi_rad = std::atan2(r(1, 0), r(0, 0));
  m.translation_mm = t;
  return m;
}

Eigen::Matrix3d ToolPose::Rotation() const {
  // Eq. 4 is an AC head's rotation, C about z then A about x: Rz(c) Rx(a). As printed it drops
  // two signs (its first two columns are not orthogonal); this is the rotation it stands for.
  return (Eigen::AngleAxisd(c_rad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(a_rad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d ToWorkpiece(const ToolPose& tool, const SensorMount& mount,
                            const Eigen::Vector3d& sensor_point) {
  return tool.Rotation() * (mount.Rotation() * sensor_point + mount.translation_mm) +
         tool.position_mm;
}

Result<MountCalibration> CalibrateMount(const std::vector<MountObservation>& observations) {
  const int n = static_cast<int>(observations.size());
  if (n < 3) {
    return InvalidArgument("mount calibration needs at least 3 points, got " + std::to_string(n));
  }
  // With the rotary axes at zero the tool frame is the workpiece frame moved by P_t.
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (int i = 0; i < n; ++i) {
    src.col(i) = observations[i].sensor_mm;
    dst.col(i) = observations[i].workpiece_mm - observations[i].tool_position_mm;
  }
  // Points on one line leave the rotation about it free.
  const Eigen::Matrix3Xd centred = src.colwise() - src.rowwise().mean();
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv(1) > 1e-6 * std::max(1.0, sv(0)))) {
    return InvalidArgument("mount calibration: the sensor's points lie on one line");
  }
  const Eigen::Matrix4d t = Eigen::umeyama(src, dst, false);
  MountCalibration cal;
  cal.mount = SensorMount::FromRotation(t.topLeftCorner<3, 3>(), t.topRightCorner<3, 1>());
  double ss = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p =
        ToWorkpiece({observations[i].tool_position_mm, 0.0, 0.0}, cal.mount, src.col(i));
    ss += (p - observations[i].workpiece_mm).squaredNorm();
  }
  cal.rms_mm = std::sqrt(ss / n);
  cal.points = n;
  return cal;
}

}  // namespace insitu::inspect
