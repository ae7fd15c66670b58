#include "insitu/calib/calibration.h"

#include <cmath>
#include <filesystem>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "insitu/core/config.h"
#include "insitu/core/file.h"
#include "insitu/optics/newton.h"

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

Status HeadCalibration::Validate() const {
  INSITU_RETURN_IF_ERROR(model.Validate());
  return pointer.Validate().Prefixed("pointer");
}

bool HeadCalibration::MarkSpot(const Eigen::Vector3d& cmd, Eigen::Vector3d* spot) const {
  if (!model.Spot(cmd, {}, spot)) return false;
  spot->head<2>() += residual_mm.At(cmd.x(), cmd.y());
  return true;
}

bool HeadCalibration::PointerRay(const Eigen::Vector3d& cmd, optics::ChiefRay* ray) const {
  return model.Land(cmd, pointer, ray);
}

bool HeadCalibration::MarkCommandFor(const Eigen::Vector3d& target, Eigen::Vector3d* cmd) const {
  if (!measured) {
    *cmd = target;
    return true;
  }
  // MarkSpot's Jacobian is within a percent of the identity over the field.
  const auto map = [&](const Eigen::Vector2d& c) {
    Eigen::Vector3d s;
    if (!MarkSpot({c.x(), c.y(), target.z()}, &s)) return Eigen::Vector2d(NAN, NAN);
    return Eigen::Vector2d(s.head<2>());
  };
  Eigen::Vector2d c = target.head<2>();
  if (!optics::InvertMap2d(map, target.head<2>(), 1e-4, 1e-7, &c)) return false;
  *cmd = Eigen::Vector3d(c.x(), c.y(), target.z());
  return true;
}

Status CalibrationSet::Validate() const {
  INSITU_RETURN_IF_ERROR(camera.Validate().Prefixed("camera"));
  INSITU_RETURN_IF_ERROR(galvo.Validate().Prefixed("galvo"));
  INSITU_RETURN_IF_ERROR(head.Validate().Prefixed("head"));
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
  set.head.model.design.telecentric = set.galvo.lens == ScanLens::kTelecentric;
  if (r.Has("head")) {
    ConfigReader& h = r.Section("head");
    HeadCalibration& head = set.head;
    h.Read("measured", &head.measured);
    h.Read("measured_by", &head.measured_by);
    const auto geometry = [](ConfigReader& s, optics::HeadGeometry* g) {
      s.Read("focal_length_mm", &g->focal_length_mm);
      s.Read("mirror_separation_mm", &g->mirror_separation_mm);
      s.Read("exit_pupil_height_mm", &g->exit_pupil_height_mm);
      s.Read("pupil_aberration", &g->pupil_aberration);
      s.Read("telecentric", &g->telecentric);
      s.Read("ftheta_c3", &g->ftheta_c3);
      s.Read("ftheta_c5", &g->ftheta_c5);
      s.Read("x_axis_tilt_mrad", &g->x_axis_tilt_mrad);
      s.Read("y_axis_tilt_mrad", &g->y_axis_tilt_mrad);
      if (s.ok()) s.FailFromValidate(g->Validate());
    };
    geometry(h.Section("design"), &head.model.design);
    head.model.built = head.model.design;
    if (h.Has("built")) geometry(h.Section("built"), &head.model.built);
    h.Read("x_zero_offset_mrad", &head.model.x_zero_offset_mrad);
    h.Read("y_zero_offset_mrad", &head.model.y_zero_offset_mrad);
    if (h.Has("pointer")) {
      ConfigReader& p = h.Section("pointer");
      p.Read("offset_x_mrad", &head.pointer.offset_x_mrad);
      p.Read("offset_y_mrad", &head.pointer.offset_y_mrad);
      p.Read("lateral_colour_pct", &head.pointer.lateral_colour_pct);
      if (p.ok()) p.FailFromValidate(head.pointer.Validate());
    }
    if (h.Has("residual")) {
      ConfigReader& t = h.Section("residual");
      std::vector<double> xs, ys, dx, dy;
      for (const char* key : {"x_mm", "y_mm", "dx_mm", "dy_mm"}) t.Require(key);
      t.Read("x_mm", &xs);
      t.Read("y_mm", &ys);
      t.Read("dx_mm", &dx);
      t.Read("dy_mm", &dy);
      if (t.ok() && dx.size() != dy.size()) t.Fail("dy_mm", "must have as many values as dx_mm");
      if (t.ok()) {
        std::vector<Eigen::Vector2d> v;
        for (size_t i = 0; i < dx.size(); ++i) v.emplace_back(dx[i], dy[i]);
        auto table = optics::GridTable::Make(xs, ys, std::move(v));
        if (table.ok()) {
          head.residual_mm = std::move(*table);
        } else {
          t.Fail("dx_mm", table.status().message());
        }
      }
    }
    if (h.ok()) h.FailFromValidate(head.model.Validate());
  }
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
  auto list = [&](const std::vector<double>& v) {
    os << "[";
    for (size_t i = 0; i < v.size(); ++i) os << (i ? ", " : "") << v[i];
    os << "]";
  };
  {
    const HeadCalibration& h = set.head;
    const auto geometry = [&](const char* name, const optics::HeadGeometry& g) {
      os << "  " << name << ":\n    focal_length_mm: " << g.focal_length_mm
         << "\n    mirror_separation_mm: " << g.mirror_separation_mm
         << "\n    exit_pupil_height_mm: " << g.exit_pupil_height_mm
         << "\n    pupil_aberration: " << g.pupil_aberration
         << "\n    telecentric: " << (g.telecentric ? "true" : "false")
         << "\n    ftheta_c3: " << g.ftheta_c3 << "\n    ftheta_c5: " << g.ftheta_c5
         << "\n    x_axis_tilt_mrad: " << g.x_axis_tilt_mrad
         << "\n    y_axis_tilt_mrad: " << g.y_axis_tilt_mrad << "\n";
    };
    os << "head:  # the scan head: design (its controller's correction) and as measured\n"
       << "  measured: " << (h.measured ? "true" : "false") << "\n  measured_by: \""
       << h.measured_by << "\"\n";
    geometry("design", h.model.design);
    geometry("built", h.model.built);
    os << "  x_zero_offset_mrad: " << h.model.x_zero_offset_mrad
       << "\n  y_zero_offset_mrad: " << h.model.y_zero_offset_mrad
       << "\n  pointer:\n    offset_x_mrad: " << h.pointer.offset_x_mrad
       << "\n    offset_y_mrad: " << h.pointer.offset_y_mrad
       << "\n    lateral_colour_pct: " << h.pointer.lateral_colour_pct << "\n";
    if (!h.residual_mm.empty()) {
      std::vector<double> dx, dy;
      for (const Eigen::Vector2d& v : h.residual_mm.values()) {
        dx.push_back(v.x());
        dy.push_back(v.y());
      }
      os << "  residual:  # what the physical model leaves at the grid nodes, row-major (y, then x)\n"
         << "    x_mm: ";
      list(h.residual_mm.xs());
      os << "\n    y_mm: ";
      list(h.residual_mm.ys());
      os << "\n    dx_mm: ";
      list(dx);
      os << "\n    dy_mm: ";
      list(dy);
      os << "\n";
    }
  }
  const HeightLookup& hl = set.height_lookup;
  if (!hl.empty()) {
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
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  if (ec) return DeviceError("cannot create directory " + parent.string() + ": " + ec.message());
  return WriteFileAtomically(path, os.str());
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
