#include "insitu/calib/calibration.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "insitu/core/config.h"

namespace insitu::calib {
namespace {

bool Finite(std::initializer_list<double> values) {
  for (double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

// Camera pose from where it stands, what it looks at and its roll: the form a machine drawing
// gives ("as designed"). Same construction as the camera mount: image 'down' points away
// from galvo +z as far as the view allows.
Eigen::Isometry3d PoseFromLookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at,
                                 double roll_deg) {
  const Eigen::Vector3d z = (look_at - position).normalized();
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-9) x = Eigen::Vector3d::UnitX();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  const double r = roll_deg * M_PI / 180.0;
  Eigen::Matrix3d galvo_from_camera_rot;
  galvo_from_camera_rot.col(0) = std::cos(r) * x + std::sin(r) * y;
  galvo_from_camera_rot.col(1) = -std::sin(r) * x + std::cos(r) * y;
  galvo_from_camera_rot.col(2) = z;
  Eigen::Isometry3d galvo_from_camera = Eigen::Isometry3d::Identity();
  galvo_from_camera.linear() = galvo_from_camera_rot;
  galvo_from_camera.translation() = position;
  return galvo_from_camera.inverse();
}

}  // namespace

Status CameraIntrinsics::Validate() const {
  if (width_px <= 0 || height_px <= 0) {
    return InvalidArgument("width_px must be > 0 (and height_px), got " +
                           std::to_string(width_px) + " x " + std::to_string(height_px));
  }
  if (!Finite({fx, fy, cx, cy, k1, k2, p1, p2, k3}) || fx <= 0 || fy <= 0) {
    return InvalidArgument("fx must be a finite positive focal length in pixels (and fy)");
  }
  return Status::Ok();
}

CameraIntrinsics CameraIntrinsics::Binned(int b) const {
  CameraIntrinsics c = *this;
  c.width_px = width_px / b;
  c.height_px = height_px / b;
  c.fx = fx / b;
  c.fy = fy / b;
  c.cx = (cx + 0.5) / b - 0.5;
  c.cy = (cy + 0.5) / b - 0.5;
  return c;
}

std::vector<Eigen::Vector2d> CameraIntrinsics::Undistort(
    const std::vector<Eigen::Vector2d>& pixels) const {
  std::vector<Eigen::Vector2d> out(pixels.size());
  if (pixels.empty()) return out;
  std::vector<cv::Point2d> src(pixels.size()), dst;
  for (size_t i = 0; i < pixels.size(); ++i) src[i] = {pixels[i].x(), pixels[i].y()};
  const cv::Matx33d k(fx, 0, cx, 0, fy, cy, 0, 0, 1);
  const cv::Vec<double, 5> dist(k1, k2, p1, p2, k3);
  // OpenCV's default 5 iterations leave ~0.05 px at the corners of a 5 MP frame; iterate to
  // 1e-6 px instead.
  cv::undistortPoints(src, dst, k, dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
  for (size_t i = 0; i < dst.size(); ++i) out[i] = {dst[i].x, dst[i].y};
  return out;
}

Eigen::Vector2d CameraIntrinsics::Project(const Eigen::Vector3d& p) const {
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  return {fx * xd + cx, fy * yd + cy};
}

Status GalvoGeometry::Validate() const {
  if (!(pivot_height_mm > 0) || !std::isfinite(pivot_height_mm)) {
    return InvalidArgument("pivot_height_mm must be > 0, got " + std::to_string(pivot_height_mm));
  }
  const Eigen::Matrix3d r = camera_from_galvo.linear();
  if (!r.allFinite() || (r * r.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-6) {
    return InvalidArgument("camera_from_galvo rotation is not a rotation");
  }
  return Status::Ok();
}

Status CalibrationSet::Validate() const {
  INSITU_RETURN_IF_ERROR(camera.Validate().Prefixed("camera"));
  INSITU_RETURN_IF_ERROR(galvo.Validate().Prefixed("galvo"));
  return Status::Ok();
}

Result<CalibrationSet> LoadCalibration(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(ConfigNode root, ConfigNode::LoadFile(path));
  CalibrationSet set;
  ConfigReader r(root);
  std::string format;
  r.Require("format");
  r.Read("format", &format);
  if (r.ok() && format != "insitu-calibration") {
    r.Fail("format", "is '" + format + "', expected 'insitu-calibration'");
  }
  r.Require("version");
  r.Read("version", &set.version);
  if (r.ok() && set.version != CalibrationSet::kFormatVersion) {
    r.Fail("version", "is " + std::to_string(set.version) + ", this build reads version " +
                          std::to_string(CalibrationSet::kFormatVersion));
  }
  r.Read("produced_by", &set.produced_by);
  r.Read("created", &set.created);

  ConfigReader& c = r.Section("camera");
  for (const char* key : {"width_px", "height_px", "fx", "fy", "cx", "cy"}) c.Require(key);
  c.Read("model", &set.camera.model);
  c.Read("serial", &set.camera.serial);
  c.Read("lens", &set.camera.lens);
  c.Read("width_px", &set.camera.width_px);
  c.Read("height_px", &set.camera.height_px);
  c.Read("fx", &set.camera.fx);
  c.Read("fy", &set.camera.fy);
  c.Read("cx", &set.camera.cx);
  c.Read("cy", &set.camera.cy);
  c.Read("k1", &set.camera.k1);
  c.Read("k2", &set.camera.k2);
  c.Read("p1", &set.camera.p1);
  c.Read("p2", &set.camera.p2);
  c.Read("k3", &set.camera.k3);
  double rms = 0;
  c.Read("rms_reprojection_px", &rms);
  if (c.ok()) c.FailFromValidate(set.camera.Validate());

  ConfigReader& g = r.Section("galvo");
  std::string lens = "f_theta";
  g.ReadEnum("lens", &lens, {"f_theta", "telecentric"});
  set.galvo.lens = lens == "telecentric" ? ScanLens::kTelecentric : ScanLens::kFTheta;
  g.Read("pivot_height_mm", &set.galvo.pivot_height_mm);
  ConfigReader& pose = g.Section("camera_from_galvo");
  if (pose.Has("rotation_rodrigues_rad")) {
    double rv[3], t[3];
    pose.ReadArray("rotation_rodrigues_rad", rv, 3);
    pose.Require("translation_mm");
    pose.ReadArray("translation_mm", t, 3);
    const Eigen::Vector3d v(rv[0], rv[1], rv[2]);
    Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
    if (v.norm() > 0) iso.linear() = Eigen::AngleAxisd(v.norm(), v.normalized()).matrix();
    iso.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
    set.galvo.camera_from_galvo = iso;
  } else {
    double pos[3] = {0, 0, 0}, at[3] = {0, 0, 0}, roll = 0;
    pose.Require("camera_position_mm");
    pose.ReadArray("camera_position_mm", pos, 3);
    pose.Require("look_at_mm");
    pose.ReadArray("look_at_mm", at, 3);
    pose.Read("roll_deg", &roll);
    set.galvo.camera_from_galvo = PoseFromLookAt({pos[0], pos[1], pos[2]},
                                                 {at[0], at[1], at[2]}, roll);
  }
  if (g.ok()) g.FailFromValidate(set.galvo.Validate());
  if (r.Has("height_lookup")) {
    ConfigReader& h = r.Section("height_lookup");
    std::vector<double> xs, zs;
    h.Require("line_x_mm");
    h.Require("stage_z_mm");
    h.Read("line_x_mm", &xs);
    h.Read("stage_z_mm", &zs);
    h.Skip("curves");
    std::vector<StripeCurve> curves;
    const ConfigNode list = h.node().Child("curves");
    for (size_t i = 0; list.IsSequence() && i < list.size(); ++i) {
      auto row = list.At(i).AsDoubleList();
      if (!row.ok() || row->size() < 3) {
        h.Fail("curves", "entry " + std::to_string(i) + " must be [u_min, u_max, c0, c1, ...]");
        break;
      }
      StripeCurve c;
      c.u_min = (*row)[0];
      c.u_max = (*row)[1];
      c.coeffs.assign(row->begin() + 2, row->end());
      curves.push_back(std::move(c));
    }
    if (h.ok()) {
      auto lookup = HeightLookup::FromParts(xs, zs, std::move(curves));
      if (lookup.ok()) {
        set.height_lookup = std::move(*lookup);
      } else {
        h.Fail("curves", lookup.status().message());
      }
    }
  }
  INSITU_RETURN_IF_ERROR(r.Finish());
  return set;
}

Status SaveCalibration(const CalibrationSet& set, const std::string& path) {
  INSITU_RETURN_IF_ERROR(set.Validate());
  std::ostringstream os;
  os.precision(12);
  const CameraIntrinsics& c = set.camera;
  os << "# insitu calibration set (format described in calib/README.md)\n"
     << "format: insitu-calibration\nversion: " << set.version << "\n"
     << "produced_by: \"" << set.produced_by << "\"\ncreated: \"" << set.created << "\"\n"
     << "camera:\n  model: \"" << c.model << "\"\n  serial: \"" << c.serial << "\"\n"
     << "  lens: \"" << c.lens << "\"\n  width_px: " << c.width_px << "\n  height_px: "
     << c.height_px << "\n  fx: " << c.fx << "\n  fy: " << c.fy << "\n  cx: " << c.cx
     << "\n  cy: " << c.cy << "\n  k1: " << c.k1 << "\n  k2: " << c.k2 << "\n  p1: " << c.p1
     << "\n  p2: " << c.p2 << "\n  k3: " << c.k3 << "\n";
  const Eigen::AngleAxisd aa(set.galvo.camera_from_galvo.linear());
  const Eigen::Vector3d rv = aa.axis() * aa.angle();
  const Eigen::Vector3d t = set.galvo.camera_from_galvo.translation();
  os << "galvo:\n  lens: " << (set.galvo.lens == ScanLens::kTelecentric ? "telecentric" : "f_theta")
     << "\n  pivot_height_mm: " << set.galvo.pivot_height_mm << "\n  camera_from_galvo:\n"
     << "    rotation_rodrigues_rad: [" << rv.x() << ", " << rv.y() << ", " << rv.z() << "]\n"
     << "    translation_mm: [" << t.x() << ", " << t.y() << ", " << t.z() << "]\n";
  const HeightLookup& hl = set.height_lookup;
  if (!hl.empty()) {
    auto list = [&](const std::vector<double>& v) {
      os << "[";
      for (size_t i = 0; i < v.size(); ++i) os << (i ? ", " : "") << v[i];
      os << "]";
    };
    os << "height_lookup:  # stripe curve v(u) of every (line offset, stage height), x-major\n"
       << "  line_x_mm: ";
    list(hl.line_x_mm());
    os << "\n  stage_z_mm: ";
    list(hl.stage_z_mm());
    os << "\n  curves:\n";
    for (const StripeCurve& c : hl.curves()) {
      std::vector<double> row{c.u_min, c.u_max};
      row.insert(row.end(), c.coeffs.begin(), c.coeffs.end());
      os << "    - ";
      list(row);
      os << "\n";
    }
  }
  const std::string tmp = path + ".tmp";
  {
    const std::filesystem::path parent = std::filesystem::path(path).parent_path();
    std::error_code ec;
    if (!parent.empty()) std::filesystem::create_directories(parent, ec);
    if (ec) return DeviceError("cannot create directory " + parent.string() + ": " + ec.message());
    std::ofstream f(tmp, std::ios::trunc);
    if (!f) return DeviceError("cannot write " + tmp);
    f << os.str();
    if (!f.good()) return DeviceError("write failed: " + tmp);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return DeviceError("cannot replace " + path);
  }
  return Status::Ok();
}

Status CheckCameraMatches(const CameraIntrinsics& cal, const std::string& model,
                          const std::string& serial, int width, int height) {
  if (!cal.model.empty() && cal.model != model) {
    return FailedPrecondition("calibration is for camera model '" + cal.model +
                              "', the machine has '" + model + "'");
  }
  if (!cal.serial.empty() && cal.serial != serial) {
    return FailedPrecondition("calibration is for camera serial '" + cal.serial +
                              "', the machine's camera is '" + serial + "'");
  }
  if (cal.width_px != width || cal.height_px != height) {
    return FailedPrecondition("calibration is for a " + std::to_string(cal.width_px) + " x " +
                              std::to_string(cal.height_px) + " sensor, the camera has " +
                              std::to_string(width) + " x " + std::to_string(height));
  }
  return Status::Ok();
}

}  // namespace insitu::calib
