#include "job/groove_cell.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include <Eigen/Geometry>

#include "insitu/core/robust.h"
#include "insitu/job/job_file.h"
#include "job/format.h"

namespace insitu::job {
namespace {

constexpr double kDeg = M_PI / 180.0;

bool Cancelled(const std::atomic<bool>* cancel) { return cancel != nullptr && cancel->load(); }

// The rims of a hole one profile crosses: walking out from the hole's centre (sensor x
// `centre`) either way, the first point that stands above half the step from the panel's top
// and starts a run on it; the rim half a point before it (the wall lies somewhere between it and
// the last point off the top, uniformly). Returns false with `why` when the profile does not
// show a hole there.
bool RimsInProfile(const hw::RangeProfile& p, double centre, double radius, double rims[2],
                   double* top_z, std::string* why) {
  std::vector<double> ring, inside;
  const int n = static_cast<int>(p.z_mm.size());
  for (int i = 0; i < n; ++i) {
    const double u = std::abs(p.x_start_mm + i * p.x_spacing_mm - centre), z = p.z_mm[i];
    if (!std::isfinite(z)) continue;
    if (u > radius + 1.0 && u < radius + 6.0) ring.push_back(z);
    if (u < 0.5 * radius) inside.push_back(z);
  }
  if (ring.size() < 10) {
    *why = "no top seen around the hole (" + std::to_string(ring.size()) + " points)";
    return false;
  }
  const double top = Median(ring), below = Median(inside);
  // Half the step to what the hole shows; a wall of at least 0.2 mm where it shows nothing (the
  // stage out of range, or in the rim's shadow).
  const double threshold =
      (std::isfinite(below) && top - below > 0.2) ? 0.5 * (top + below) : top - 0.2;
  constexpr int kRun = 4;
  const int c = static_cast<int>(std::lround((centre - p.x_start_mm) / p.x_spacing_mm));
  const int reach = static_cast<int>(std::ceil((radius + 6.0) / p.x_spacing_mm));
  for (int side = 0; side < 2; ++side) {
    const int step = side == 0 ? -1 : 1;
    bool found = false;
    for (int k = 0; k <= reach && !found; ++k) {
      const int i = c + step * k;
      bool run = true;
      for (int j = 0; j < kRun && run; ++j) {
        const int q = i + step * j;
        run = q >= 0 && q < n && std::isfinite(p.z_mm[q]) && p.z_mm[q] > threshold;
      }
      if (!run) continue;
      if (k == 0) {
        *why = Fmt("the top (%.3f mm) runs through where the hole's centre should be", top);
        return false;
      }
      rims[side] = p.x_start_mm + (i - 0.5 * step) * p.x_spacing_mm;
      found = true;
    }
    if (!found) {
      *why = Fmt("no rim within %.1f mm of the hole's centre on one side", radius + 6.0);
      return false;
    }
  }
  *top_z = top;
  return true;
}

}  // namespace

inspect::SensorMount MountFromPose(const std::array<double, 6>& p) {
  inspect::SensorMount m;
  m.translation_mm = {p[0], p[1], p[2]};
  m.psi_rad = p[3] * kDeg;
  m.theta_rad = p[4] * kDeg;
  m.phi_rad = p[5] * kDeg;
  return m;
}

std::array<double, 6> PoseFromMount(const inspect::SensorMount& m) {
  return {m.translation_mm.x(), m.translation_mm.y(), m.translation_mm.z(),
          m.psi_rad / kDeg,     m.theta_rad / kDeg,   m.phi_rad / kDeg};
}

Status SaveMount(const inspect::MountCalibration& c, const hw::ProfilerInfo& profiler,
                 const std::string& path) {
  const std::array<double, 6> p = PoseFromMount(c.mount);
  std::ofstream f(path, std::ios::trunc);
  if (!f) return NotFound("cannot write " + path);
  f.precision(10);
  f << "# The line profiler's mounting on the tool (seed 002 eq. 8), calibrated on the block:\n"
    << "# the sensor frame in the tool frame, mm and deg (rotations about x, then y, then z).\n"
    << "profiler:\n  model: \"" << profiler.model << "\"\n  serial: \"" << profiler.serial
    << "\"\nmount:\n  translation_mm: [" << p[0] << ", " << p[1] << ", " << p[2]
    << "]\n  rotation_deg: [" << p[3] << ", " << p[4] << ", " << p[5] << "]\n"
    << "fit:\n  rms_mm: " << c.rms_mm << "\n  points: " << c.points << "\n";
  if (!f.good()) return Status(StatusCode::kDeviceError, "write failed: " + path);
  return Status::Ok();
}

Result<inspect::SensorMount> LoadMount(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(ConfigNode root, ConfigNode::LoadFile(path));
  ConfigReader r(root);
  std::array<double, 6> p{};
  ConfigReader& m = r.Section("mount");
  m.Require("translation_mm");
  m.Require("rotation_deg");
  m.ReadArray("translation_mm", p.data(), 3);
  m.ReadArray("rotation_deg", p.data() + 3, 3);
  r.Skip("profiler");
  r.Skip("fit");
  INSITU_RETURN_IF_ERROR(r.Finish());
  return MountFromPose(p);
}

inspect::ToolPose ToolFromAxes(const hw::AxisPose& a) {
  inspect::ToolPose t;
  t.position_mm = {a.x_mm, a.y_mm, a.z_mm};
  t.a_rad = a.a_deg * kDeg;
  t.c_rad = a.c_deg * kDeg;
  return t;
}

hw::AxisPose AxesForSensorAt(const inspect::SensorMount& mount, const Eigen::Vector3d& target,
                             const Eigen::Vector2d& line_xy) {
  // The sensor's x in the tool frame, seen from above, and the turn that lays it on the line.
  const Eigen::Vector3d sx = mount.Rotation().col(0);
  double c = std::atan2(line_xy.y(), line_xy.x()) - std::atan2(sx.y(), sx.x());
  c = std::remainder(c, M_PI);  // (-90, 90] deg: either way round crosses the groove
  if (c <= -M_PI / 2) c += M_PI;
  const Eigen::Matrix3d rc = Eigen::AngleAxisd(c, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d tool = target - rc * mount.translation_mm;
  hw::AxisPose a;
  a.x_mm = tool.x();
  a.y_mm = tool.y();
  a.z_mm = tool.z();
  a.c_deg = c / kDeg;
  return a;
}

Eigen::Vector3d ProfilePointInMachine(const hw::AxisPose& axes, const inspect::SensorMount& mount,
                                      double x_mm, double z_mm) {
  return inspect::ToWorkpiece(ToolFromAxes(axes), mount, inspect::SensorPoint(x_mm, z_mm));
}

double SensorXOf(const hw::AxisPose& axes, const inspect::SensorMount& mount,
                 const Eigen::Vector3d& machine_point) {
  const inspect::ToolPose t = ToolFromAxes(axes);
  const Eigen::Vector3d in_tool = t.Rotation().transpose() * (machine_point - t.position_mm);
  return (mount.Rotation().transpose() * (in_tool - mount.translation_mm)).x();
}

Eigen::Vector2d PanelFrame::ToWorkpiece(const Eigen::Vector2d& q) const {
  const Eigen::Vector2d d = q - origin_mm;
  return {d.dot(x_axis), d.dot(y_axis)};
}

Eigen::Vector2d PanelFrame::ToMachine(const Eigen::Vector2d& w) const {
  return origin_mm + w.x() * x_axis + w.y() * y_axis;
}

double PanelFrame::rotation_deg() const { return std::atan2(x_axis.y(), x_axis.x()) / kDeg; }

PanelFrame PanelFrame::FromHoles(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                 double distance_mm, double top_z) {
  PanelFrame f;
  f.x_axis = (b - a).normalized();
  f.origin_mm = 0.5 * (a + b) - 0.5 * distance_mm * f.x_axis;
  f.y_axis = {-f.x_axis.y(), f.x_axis.x()};
  f.top_z_mm = top_z;
  return f;
}

Result<Circle2> FitCircle2(const std::vector<Eigen::Vector2d>& p) {
  if (p.size() < 3) return FailedPrecondition("a circle needs 3 points, got " + std::to_string(p.size()));
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& q : p) mean += q;
  mean /= static_cast<double>(p.size());
  // Kasa: x^2 + y^2 + D x + E y + F = 0, about the mean for conditioning.
  Eigen::MatrixXd a(p.size(), 3);
  Eigen::VectorXd rhs(p.size());
  for (size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector2d d = p[i] - mean;
    a.row(i) << d.x(), d.y(), 1.0;
    rhs(i) = -d.squaredNorm();
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
  if (qr.rank() < 3) return FailedPrecondition("the rim points lie on a line");
  const Eigen::Vector3d s = qr.solve(rhs);
  Circle2 c;
  c.centre = mean + Eigen::Vector2d(-0.5 * s(0), -0.5 * s(1));
  c.radius = std::sqrt(std::max(0.0, 0.25 * (s(0) * s(0) + s(1) * s(1)) - s(2)));
  // Gauss-Newton on the geometric distances (Kasa's fit leans toward the points' side).
  for (int it = 0; it < 20; ++it) {
    Eigen::MatrixXd j(p.size(), 3);
    Eigen::VectorXd r(p.size());
    for (size_t i = 0; i < p.size(); ++i) {
      const Eigen::Vector2d d = p[i] - c.centre;
      const double len = std::max(d.norm(), 1e-12);
      r(i) = len - c.radius;
      j.row(i) << -d.x() / len, -d.y() / len, -1.0;
    }
    const Eigen::Vector3d step = j.colPivHouseholderQr().solve(-r);
    c.centre += step.head<2>();
    c.radius += step(2);
    if (step.norm() < 1e-10) break;
  }
  double ss = 0;
  for (const auto& q : p) ss += std::pow((q - c.centre).norm() - c.radius, 2);
  c.rms = std::sqrt(ss / static_cast<double>(p.size()));
  return c;
}

Status DatumSpec::Validate() const {
  if (!(hole_a_mm.allFinite() && hole_b_mm.allFinite() && std::isfinite(top_z_mm)))
    return InvalidArgument("hole_a_mm, hole_b_mm and top_z_mm must be finite");
  if (!(hole_diameter_mm > 0.5 && hole_diameter_mm < 50))
    return InvalidArgument("hole_diameter_mm must be in (0.5, 50)");
  if (!((hole_b_mm - hole_a_mm).norm() > 2 * hole_diameter_mm))
    return InvalidArgument("hole_a_mm and hole_b_mm must be apart by more than two diameters");
  if (profiles_per_hole < 3 || profiles_per_hole > 200)
    return InvalidArgument("profiles_per_hole must be in [3, 200]");
  return Status::Ok();
}

Result<DatumResult> MeasureDatums(hw::Axis& axis, hw::Profiler& profiler,
                                  const inspect::SensorMount& mount, const DatumSpec& spec,
                                  const std::atomic<bool>* cancel) {
  INSITU_RETURN_IF_ERROR(spec.Validate());
  const double r = 0.5 * spec.hole_diameter_mm;
  DatumResult out;
  std::vector<double> tops;
  double ss = 0;
  for (int h = 0; h < 2; ++h) {
    const char* name = h == 0 ? "tooling hole A" : "tooling hole B";
    const Eigen::Vector2d nominal = h == 0 ? spec.hole_a_mm : spec.hole_b_mm;
    std::vector<Eigen::Vector2d> rim;
    for (int k = 0; k < spec.profiles_per_hole; ++k) {
      if (Cancelled(cancel)) return Status(StatusCode::kCancelled, "cancelled");
      // Chords across the middle 70 % of the hole (the rim steep to the line there).
      const double t = 0.7 * r * (2.0 * k / (spec.profiles_per_hole - 1.0) - 1.0);
      const Eigen::Vector3d target(nominal.x(), nominal.y() + t, spec.top_z_mm);
      INSITU_RETURN_IF_ERROR(axis.MoveTo(AxesForSensorAt(mount, target, Eigen::Vector2d::UnitX()))
                                 .Prefixed(std::string(name) + ": move"));
      INSITU_ASSIGN_OR_RETURN(const hw::AxisPose axes, axis.Position());
      INSITU_ASSIGN_OR_RETURN(const hw::RangeProfile p, profiler.Grab());
      double rims[2], top = 0;
      std::string why;
      if (!RimsInProfile(p, SensorXOf(axes, mount, target), r, rims, &top, &why)) {
        return FailedPrecondition(std::string(name) + Fmt(" not seen (chord %.2f mm off its centre): ", t) + why);
      }
      for (double x : rims) {
        const Eigen::Vector3d q = ProfilePointInMachine(axes, mount, x, top);
        rim.push_back(q.head<2>());
        tops.push_back(q.z());
      }
    }
    auto circle = FitCircle2(rim);
    if (!circle.ok()) return circle.status().Prefixed(name);
    // The profiler places each rim to its point spacing (~7 um rms at 25 um): a circle 0.1 mm
    // off the drawing's, or rims 50 um off it, is another feature or a misread rim.
    if (std::abs(2.0 * circle->radius - spec.hole_diameter_mm) > 0.1 || circle->rms > 0.05) {
      return FailedPrecondition(std::string(name) +
                                Fmt(": its rims make a %.3f mm circle (rms %.0f um), not the "
                                    "drawing's %.2f mm hole",
                                    2.0 * circle->radius, 1e3 * circle->rms,
                                    spec.hole_diameter_mm));
    }
    out.hole_mm[h] = circle->centre;
    out.hole_diameter_mm[h] = 2.0 * circle->radius;
    ss += circle->rms * circle->rms * rim.size();
    out.rim_points += static_cast<int>(rim.size());
  }
  out.rim_rms_mm = std::sqrt(ss / out.rim_points);
  out.frame = PanelFrame::FromHoles(out.hole_mm[0], out.hole_mm[1],
                                    (spec.hole_b_mm - spec.hole_a_mm).norm(), Median(tops));
  return out;
}

Status BlockScanSpec::Validate() const {
  if (!centre_mm.allFinite()) return InvalidArgument("centre_mm must be finite");
  if (!(extent_mm > 1 && extent_mm < 1000)) return InvalidArgument("extent_mm must be in (1, 1000)");
  if (profiles_per_direction < 2 || profiles_per_direction > 500)
    return InvalidArgument("profiles_per_direction must be in [2, 500]");
  return Status::Ok();
}

Result<inspect::MountCalibration> CalibrateMountOnBlock(hw::Axis& axis, hw::Profiler& profiler,
                                                        const inspect::CalibrationBlock& block,
                                                        const inspect::SensorMount& drawing,
                                                        const BlockScanSpec& spec,
                                                        const std::atomic<bool>* cancel) {
  INSITU_RETURN_IF_ERROR(spec.Validate());
  // The sensor's reference point at mid-height of the block, so its range spans the plate
  // and the pyramid's top.
  double top = 0;
  for (const inspect::BlockFace& f : block.faces) {
    for (const Eigen::Vector3d& v : f.outline_mm) top = std::max(top, v.z() - spec.centre_mm.z());
  }
  std::vector<inspect::BlockScan> scans;
  for (int dir = 0; dir < 2; ++dir) {
    const Eigen::Vector2d line = dir == 0 ? Eigen::Vector2d::UnitX() : Eigen::Vector2d::UnitY();
    const Eigen::Vector2d step = dir == 0 ? Eigen::Vector2d::UnitY() : Eigen::Vector2d::UnitX();
    for (int k = 0; k < spec.profiles_per_direction; ++k) {
      if (Cancelled(cancel)) return Status(StatusCode::kCancelled, "cancelled");
      const double s = spec.extent_mm * (k / (spec.profiles_per_direction - 1.0) - 0.5);
      const Eigen::Vector2d at = spec.centre_mm.head<2>() + s * step;
      const Eigen::Vector3d target(at.x(), at.y(), spec.centre_mm.z() + 0.5 * top);
      INSITU_RETURN_IF_ERROR(axis.MoveTo(AxesForSensorAt(drawing, target, line)).Prefixed("block: move"));
      INSITU_ASSIGN_OR_RETURN(const hw::AxisPose axes, axis.Position());
      INSITU_ASSIGN_OR_RETURN(const hw::RangeProfile p, profiler.Grab());
      inspect::BlockScan scan;
      scan.tool = ToolFromAxes(axes);
      for (size_t i = 0; i < p.z_mm.size(); ++i) {
        if (!std::isfinite(p.z_mm[i])) continue;
        scan.sensor_points.push_back(
            inspect::SensorPoint(p.x_start_mm + static_cast<double>(i) * p.x_spacing_mm, p.z_mm[i]));
      }
      scans.push_back(std::move(scan));
    }
  }
  return inspect::CalibrateMountFromBlock(scans, block, drawing);
}

void ReadProfilerSection(ConfigReader& r, const std::string& folder, ProfilerSpec* spec) {
  r.ReadArray("mount", spec->drawing.data(), 6);
  std::string mount_file;
  r.Read("mount_file", &mount_file);
  if (!mount_file.empty()) spec->mount_file = ResolvePath(folder, mount_file);
  if (r.Has("block")) {
    ConfigReader& b = r.Section("block");
    std::string file;
    b.Read("file", &file);
    if (!file.empty()) spec->block_file = ResolvePath(folder, file);
    b.ReadArray("centre_mm", spec->block_scan.centre_mm.data(), 3);
    b.Read("base_mm", &spec->pyramid.base_mm);
    b.Read("top_mm", &spec->pyramid.top_mm);
    b.Read("height_mm", &spec->pyramid.height_mm);
    b.Read("plate_mm", &spec->pyramid.plate_mm);
    b.Read("extent_mm", &spec->block_scan.extent_mm);
    b.Read("profiles_per_direction", &spec->block_scan.profiles_per_direction);
    if (b.ok()) b.FailFromValidate(spec->pyramid.Validate());
    if (b.ok()) b.FailFromValidate(spec->block_scan.Validate());
  }
  if (r.Has("datums")) {
    ConfigReader& d = r.Section("datums");
    DatumSpec& ds = spec->datums;
    d.ReadArray("hole_a_mm", ds.hole_a_mm.data(), 2);
    d.ReadArray("hole_b_mm", ds.hole_b_mm.data(), 2);
    d.Read("hole_diameter_mm", &ds.hole_diameter_mm);
    d.Read("top_z_mm", &ds.top_z_mm);
    d.Read("profiles_per_hole", &ds.profiles_per_hole);
    if (d.ok()) d.FailFromValidate(ds.Validate());
  }
}

Result<inspect::CalibrationBlock> BlockOf(const ProfilerSpec& spec) {
  if (!spec.block_file.empty()) return inspect::LoadCalibrationBlock(spec.block_file);
  return inspect::PyramidBlock(spec.block_scan.centre_mm, spec.pyramid);
}

}  // namespace insitu::job
