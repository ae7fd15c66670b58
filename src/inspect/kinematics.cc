#include "insitu/inspect/kinematics.h"

#include <ceres/tiny_solver.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <set>

#include "insitu/core/config.h"
#include "insitu/core/robust.h"

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

// Calibration from profiles of a block of planar faces.
//
// Each profile point, taken to the workpiece by eq. 1 under the current mount, is assigned to
// the nearest face whose outline contains its projection; its residual is its distance to that
// face's plane. A point on a plane fixes only its distance, so the faces seen must face enough
// directions: the pyramid's sides give the two horizontal ones, its top and the plate the
// vertical one. Points are assigned afresh after each solve (as in point-to-plane ICP) under a
// gate that starts wide enough for the builder's drawing and halves at most per round down to
// a few robust standard deviations of the residuals: an early, wrong estimate cannot shrink it
// onto a subset that agrees with itself, and the spikes and the table around the block fall out
// as it closes. Edges are left out by a margin: a reading there mixes two faces, and the CMM
// report's planes do not describe the rounding.
//
// The six parameters are eq. 8's angles and the translation, solved by Levenberg-Marquardt
// (Ceres's TinySolver, analytic Jacobian); mounts are far from theta = +-90 deg, where eq. 8's
// angles lock. Whether the scans determine them is read from the Jacobian at the solution with
// each angle scaled by the points' lever about its axis (rad x lever_mm is how far the angle
// moves the points): the normal matrix N = J^T J / m in those units bounds the change of each
// parameter that any systematic error of rms e in the residuals can cause by sqrt(N^-1_jj) e
// (the error gain; Dy = (J^T J)^-1 J^T e, at its largest for e along J's column space). With the
// points' spread as the unit, the gain does not depend on how many points there are: it
// measures the geometry, which no number of points makes up for. A parameter in N's null space
// (no scan sees it) or of a large gain is refused by name rather than returned as a number that
// the noise happens to give.
namespace {

constexpr double kFaceOffPlaneMm = 0.1;  // an outline vertex's distance to its plane, at most
constexpr double kUnitNormalTolerance = 1e-6;
constexpr double kFileNormalTolerance = 0.01;  // a file's normal is normalised within this
constexpr double kSettledMm = 1e-6;  // a round that moves the mount less than this has settled

// A face's plane with an in-plane basis, and its outline in that basis, counterclockwise about
// the normal, with the inward unit normal of each edge.
struct FaceFrame {
  Eigen::Vector3d normal, point, e1, e2;
  std::vector<Eigen::Vector2d> vertices, inward;

  Eigen::Vector2d InPlane(const Eigen::Vector3d& p) const {
    return {e1.dot(p - point), e2.dot(p - point)};
  }
  // Whether uv lies inside the outline, at least margin_mm from its edges.
  bool Contains(const Eigen::Vector2d& uv, double margin_mm) const {
    for (size_t i = 0; i < vertices.size(); ++i) {
      if (inward[i].dot(uv - vertices[i]) < margin_mm) return false;
    }
    return true;
  }
};

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

struct FaceProblem {
  std::string field;  // "normal", "point_mm", "outline_mm"
  std::string what;
};

// The face's frame, or what is wrong with it. `normal_tolerance`: how far from unit length the
// normal may be (it is normalised).
std::optional<FaceProblem> MakeFrame(const BlockFace& face, double normal_tolerance,
                                     FaceFrame* frame) {
  char text[160];
  const double length = face.normal.norm();
  if (!face.normal.allFinite() || !(std::abs(length - 1.0) <= normal_tolerance)) {
    std::snprintf(text, sizeof(text), "has length %.6g, expected a unit vector", length);
    return FaceProblem{"normal", text};
  }
  if (!face.point_mm.allFinite()) return FaceProblem{"point_mm", "is not finite"};
  const int n = static_cast<int>(face.outline_mm.size());
  if (n < 3) {
    return FaceProblem{"outline_mm", "has " + std::to_string(n) +
                                         " vertices, expected a convex polygon of at least 3"};
  }
  frame->normal = face.normal / length;
  frame->point = face.point_mm;
  frame->e1 = frame->normal.unitOrthogonal();
  frame->e2 = frame->normal.cross(frame->e1);
  frame->vertices.clear();
  double area = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d& v = face.outline_mm[i];
    const double off = std::abs(frame->normal.dot(v - face.point_mm));
    if (!v.allFinite() || !(off <= kFaceOffPlaneMm)) {
      std::snprintf(text, sizeof(text),
                    "vertex %d lies %.3g mm off the face's plane, expected within %.3g mm", i + 1,
                    off, kFaceOffPlaneMm);
      return FaceProblem{"outline_mm", text};
    }
    frame->vertices.push_back(frame->InPlane(v));
  }
  for (int i = 0; i < n; ++i) area += Cross2(frame->vertices[i], frame->vertices[(i + 1) % n]);
  if (area < 0) std::reverse(frame->vertices.begin(), frame->vertices.end());
  // Convex and simple: every turn to the left and the turns adding up to one full turn (a star
  // turns left everywhere too, twice round).
  double turning = 0, perimeter = 0;
  frame->inward.clear();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d d = frame->vertices[(i + 1) % n] - frame->vertices[i];
    const Eigen::Vector2d next = frame->vertices[(i + 2) % n] - frame->vertices[(i + 1) % n];
    perimeter += d.norm();
    if (!(d.norm() > 1e-9)) return FaceProblem{"outline_mm", "has two equal vertices in a row"};
    if (Cross2(d, next) < -1e-9 * d.norm() * next.norm()) {
      return FaceProblem{"outline_mm", "is not convex, expected a convex polygon"};
    }
    turning += std::atan2(Cross2(d, next), d.dot(next));
    frame->inward.push_back(Eigen::Vector2d(-d.y(), d.x()) / d.norm());
  }
  if (!(std::abs(area) > 1e-6 * perimeter * perimeter)) {
    return FaceProblem{"outline_mm", "encloses no area, expected a convex polygon"};
  }
  if (std::abs(turning - 2 * M_PI) > 1e-6) {
    return FaceProblem{"outline_mm", "crosses itself, expected a convex polygon"};
  }
  return std::nullopt;
}

std::string FaceLabel(const BlockFace& face, size_t index) {
  return face.name.empty() ? "face " + std::to_string(index + 1) : "face '" + face.name + "'";
}

// The six parameters as one vector, in the order of kMountParameterNames.
using MountParameters = Eigen::Matrix<double, 6, 1>;

MountParameters ToParameters(const SensorMount& m) {
  MountParameters q;
  q << m.theta_rad, m.psi_rad, m.phi_rad, m.translation_mm;
  return q;
}

SensorMount ToMount(const MountParameters& q) {
  SensorMount m;
  m.theta_rad = q[0];
  m.psi_rad = q[1];
  m.phi_rad = q[2];
  m.translation_mm = q.tail<3>();
  return m;
}

// A profile point with its tool pose.
struct Sample {
  Eigen::Vector3d sensor_mm;
  Eigen::Matrix3d tool_rotation;
  Eigen::Vector3d tool_position_mm;
};

// Each sample's face under `mount` (-1: none), by the rule in the header.
void AssignFaces(const std::vector<Sample>& samples, const std::vector<FaceFrame>& faces,
                 const SensorMount& mount, double gate_mm, double margin_mm,
                 std::vector<int>* face_of) {
  const Eigen::Matrix3d r = mount.Rotation();
  face_of->assign(samples.size(), -1);
  for (size_t i = 0; i < samples.size(); ++i) {
    const Sample& s = samples[i];
    const Eigen::Vector3d p =
        s.tool_rotation * (r * s.sensor_mm + mount.translation_mm) + s.tool_position_mm;
    double nearest = gate_mm;
    for (size_t f = 0; f < faces.size(); ++f) {
      const double d = std::abs(faces[f].normal.dot(p - faces[f].point));
      if (d <= nearest && faces[f].Contains(faces[f].InPlane(p), margin_mm)) {
        nearest = d;
        (*face_of)[i] = static_cast<int>(f);
      }
    }
  }
}

// One residual of eq. 10 in point-to-plane form: n . (R_t (R s + t) + P_t - q), written in the
// tool frame so that the mount is all that varies.
struct PlaneRow {
  Eigen::Vector3d sensor_mm;
  Eigen::Vector3d normal_in_tool;  // R_t^T n
  double offset_mm;                // n . (P_t - q)
};

class PointToPlane {
 public:
  using Scalar = double;
  enum { NUM_RESIDUALS = Eigen::Dynamic, NUM_PARAMETERS = 6 };

  explicit PointToPlane(const std::vector<PlaneRow>& rows) : rows_(rows) {}
  int NumResiduals() const { return static_cast<int>(rows_.size()); }

  bool operator()(const double* q, double* residuals, double* jacobian) const {
    using Eigen::Vector3d;
    const Eigen::Matrix3d rx = Eigen::AngleAxisd(q[1], Vector3d::UnitX()).toRotationMatrix();
    const Eigen::Matrix3d ry = Eigen::AngleAxisd(q[0], Vector3d::UnitY()).toRotationMatrix();
    const Eigen::Matrix3d rz = Eigen::AngleAxisd(q[2], Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Matrix3d rzy = rz * ry;
    const Vector3d t(q[3], q[4], q[5]);
    const int n = NumResiduals();
    for (int i = 0; i < n; ++i) {
      const PlaneRow& row = rows_[i];
      const Vector3d a = rx * row.sensor_mm;  // eq. 8: R = Rz(phi) Ry(theta) Rx(psi)
      const Vector3d b = ry * a;
      const Vector3d p = rz * b;
      const Vector3d& m = row.normal_in_tool;
      residuals[i] = m.dot(p + t) + row.offset_mm;
      if (jacobian != nullptr) {
        // Column-major, n rows. Each angle turns what lies after it about its own axis.
        jacobian[0 * n + i] = m.dot(rz * Vector3d::UnitY().cross(b));
        jacobian[1 * n + i] = m.dot(rzy * Vector3d::UnitX().cross(a));
        jacobian[2 * n + i] = m.dot(Vector3d::UnitZ().cross(p));
        jacobian[3 * n + i] = m.x();
        jacobian[4 * n + i] = m.y();
        jacobian[5 * n + i] = m.z();
      }
    }
    return true;
  }

 private:
  const std::vector<PlaneRow>& rows_;
};

std::vector<PlaneRow> MakeRows(const std::vector<Sample>& samples,
                               const std::vector<FaceFrame>& faces,
                               const std::vector<int>& face_of) {
  std::vector<PlaneRow> rows;
  for (size_t i = 0; i < samples.size(); ++i) {
    if (face_of[i] < 0) continue;
    const FaceFrame& f = faces[face_of[i]];
    const Sample& s = samples[i];
    rows.push_back({s.sensor_mm, s.tool_rotation.transpose() * f.normal,
                    f.normal.dot(s.tool_position_mm - f.point)});
  }
  return rows;
}

// A robust standard deviation of values about zero: 1.4826 times their median absolute value.
double RobustSigma(const Eigen::VectorXd& r) {
  return kMadToSigma * MedianAbsDeviationFrom(std::vector<double>(r.begin(), r.end()), 0.0);
}

}  // namespace

Status CalibrationBlock::Validate() const {
  if (faces.empty()) return InvalidArgument("calibration block '" + name + "' has no faces");
  std::set<std::string> names;
  for (size_t i = 0; i < faces.size(); ++i) {
    if (faces[i].name.empty()) {
      return InvalidArgument(FaceLabel(faces[i], i) + ": name is empty, expected a name");
    }
    if (!names.insert(faces[i].name).second) {
      return InvalidArgument(FaceLabel(faces[i], i) + ": name is taken by another face");
    }
    FaceFrame frame;
    if (auto problem = MakeFrame(faces[i], kUnitNormalTolerance, &frame)) {
      return InvalidArgument(FaceLabel(faces[i], i) + ": " + problem->field + " " + problem->what);
    }
  }
  return Status::Ok();
}

Status PyramidBlockSize::Validate() const {
  if (!(top_mm > 0)) return InvalidArgument("top_mm must be > 0");
  if (!(base_mm > top_mm)) return InvalidArgument("base_mm must be larger than top_mm");
  if (!(plate_mm > base_mm)) return InvalidArgument("plate_mm must be larger than base_mm");
  if (!(height_mm > 0)) return InvalidArgument("height_mm must be > 0");
  return Status::Ok();
}

Result<CalibrationBlock> PyramidBlock(const Eigen::Vector3d& base_centre_mm,
                                      const PyramidBlockSize& size) {
  INSITU_RETURN_IF_ERROR(size.Validate());
  using Eigen::Vector3d;
  const double b = size.base_mm / 2, a = size.top_mm / 2, h = size.height_mm, p = size.plate_mm / 2;
  const Vector3d& c = base_centre_mm;
  CalibrationBlock block;
  block.name = "pyramid";
  const auto add = [&](const std::string& name, const Vector3d& normal,
                       const std::vector<Vector3d>& outline) {
    BlockFace face{name, normal.normalized(), c, {}};
    Vector3d centroid = Vector3d::Zero();
    for (const Vector3d& v : outline) {
      face.outline_mm.push_back(c + v);
      centroid += v / outline.size();
    }
    face.point_mm += centroid;
    block.faces.push_back(face);
  };
  // Outlines counterclockwise seen from outside the block.
  add("top", Vector3d::UnitZ(), {{-a, -a, h}, {a, -a, h}, {a, a, h}, {-a, a, h}});
  add("side +x", {h, 0, b - a}, {{b, -b, 0}, {b, b, 0}, {a, a, h}, {a, -a, h}});
  add("side -x", {-h, 0, b - a}, {{-b, b, 0}, {-b, -b, 0}, {-a, -a, h}, {-a, a, h}});
  add("side +y", {0, h, b - a}, {{b, b, 0}, {-b, b, 0}, {-a, a, h}, {a, a, h}});
  add("side -y", {0, -h, b - a}, {{-b, -b, 0}, {b, -b, 0}, {a, -a, h}, {-a, -a, h}});
  add("plate", Vector3d::UnitZ(), {{-p, -p, 0}, {p, -p, 0}, {p, p, 0}, {-p, p, 0}});
  return block;
}

namespace {

Result<CalibrationBlock> ReadBlock(const ConfigNode& root) {
  CalibrationBlock block;
  ConfigReader r(root);
  r.Read("name", &block.name);
  r.Require("faces");
  r.Skip("faces");
  INSITU_RETURN_IF_ERROR(r.Finish());
  const ConfigNode faces = root.Child("faces");
  if (!faces.IsSequence() || faces.size() == 0) {
    return InvalidArgument(faces.Where() + ": is not a list of faces, expected one entry a face");
  }
  for (size_t i = 0; i < faces.size(); ++i) {
    const ConfigNode node = faces.At(i);
    BlockFace face;
    ConfigReader f(node);
    f.Read("name", &face.name);
    f.ReadArray("normal", face.normal.data(), 3);
    f.ReadArray("point_mm", face.point_mm.data(), 3);
    f.Skip("outline_mm");
    // After the reads, so that a missing field's message says what it expected.
    for (const char* key : {"name", "normal", "point_mm", "outline_mm"}) f.Require(key);
    const std::string label = " (" + FaceLabel(face, i) + ")";
    const Status read = f.Finish();
    if (!read.ok()) return Status(read.code(), read.message() + label);
    const ConfigNode outline = node.Child("outline_mm");
    if (!outline.IsSequence()) {
      return InvalidArgument(outline.Where() +
                             ": is not a list of vertices, expected [[x, y, z], ...]" + label);
    }
    for (size_t k = 0; k < outline.size(); ++k) {
      Result<std::vector<double>> v = outline.At(k).AsDoubleList();
      if (!v.ok()) return Status(v.status().code(), v.status().message() + label);
      if (v->size() != 3) {
        return InvalidArgument(outline.At(k).Where() + ": has " + std::to_string(v->size()) +
                               " numbers, expected [x, y, z]" + label);
      }
      face.outline_mm.emplace_back((*v)[0], (*v)[1], (*v)[2]);
    }
    for (size_t j = 0; j < i; ++j) {
      if (block.faces[j].name == face.name) {
        return InvalidArgument(node.Child("name").Where() + ": '" + face.name +
                               "' is taken by faces[" + std::to_string(j) +
                               "], expected each face named once");
      }
    }
    FaceFrame frame;
    if (auto problem = MakeFrame(face, kFileNormalTolerance, &frame)) {
      return InvalidArgument(node.Child(problem->field).Where() + ": " + problem->what + label);
    }
    face.normal = frame.normal;
    block.faces.push_back(face);
  }
  return block;
}

}  // namespace

Result<CalibrationBlock> ParseCalibrationBlock(const std::string& text, const std::string& origin) {
  INSITU_ASSIGN_OR_RETURN(ConfigNode root, ConfigNode::Parse(text, origin));
  return ReadBlock(root);
}

Result<CalibrationBlock> LoadCalibrationBlock(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(ConfigNode root, ConfigNode::LoadFile(path));
  return ReadBlock(root);
}

Status BlockCalibrationOptions::Validate() const {
  if (!(initial_gate_mm > 0)) return InvalidArgument("initial_gate_mm must be > 0");
  if (!(gate_sigmas > 0)) return InvalidArgument("gate_sigmas must be > 0");
  if (!(min_gate_mm > 0)) return InvalidArgument("min_gate_mm must be > 0");
  if (!(edge_margin_mm >= 0)) return InvalidArgument("edge_margin_mm must be >= 0");
  if (max_rounds < 1) return InvalidArgument("max_rounds must be >= 1");
  if (max_iterations < 1) return InvalidArgument("max_iterations must be >= 1");
  if (!(max_error_gain > 0)) return InvalidArgument("max_error_gain must be > 0");
  return Status::Ok();
}

Result<MountCalibration> CalibrateMountFromBlock(const std::vector<BlockScan>& scans,
                                                 const CalibrationBlock& block,
                                                 const SensorMount& initial,
                                                 const BlockCalibrationOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  INSITU_RETURN_IF_ERROR(block.Validate());
  std::vector<FaceFrame> faces(block.faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    MakeFrame(block.faces[f], kUnitNormalTolerance, &faces[f]);
  }
  std::vector<Sample> samples;
  for (const BlockScan& scan : scans) {
    const Eigen::Matrix3d rt = scan.tool.Rotation();
    for (const Eigen::Vector3d& s : scan.sensor_points) {
      if (s.allFinite()) samples.push_back({s, rt, scan.tool.position_mm});
    }
  }

  MountParameters q = ToParameters(initial);
  double gate_mm = options.initial_gate_mm;
  std::vector<int> face_of, next_face_of;
  std::vector<PlaneRow> rows;
  AssignFaces(samples, faces, initial, gate_mm, options.edge_margin_mm, &face_of);
  int round = 1;
  for (;; ++round) {
    rows = MakeRows(samples, faces, face_of);
    if (rows.size() < 6) {
      char text[200];
      std::snprintf(text, sizeof(text),
                    "mount calibration: %zu of %zu points lie within %.3g mm of a face of the "
                    "block, expected at least 6: is the block where the scans looked, the initial "
                    "mount within a few mm and degrees?",
                    rows.size(), samples.size(), gate_mm);
      return FailedPrecondition(text);
    }
    const PointToPlane problem(rows);
    ceres::TinySolver<PointToPlane> solver;
    solver.options.max_num_iterations = options.max_iterations;
    solver.options.gradient_tolerance = 1e-14;
    solver.options.parameter_tolerance = 1e-12;
    solver.options.function_tolerance = 1e-14;
    MountParameters solved = q;
    solver.Solve(problem, &solved);
    if (!solved.allFinite()) return Internal("mount calibration: the solver left the mount");
    Eigen::VectorXd r(rows.size());
    problem(solved.data(), r.data(), nullptr);
    // The gate moves in steps of at least a fifth, so that it settles.
    const double target = std::max(options.min_gate_mm, options.gate_sigmas * RobustSigma(r));
    const bool gate_settled = !(target < 0.8 * gate_mm);
    if (!gate_settled) gate_mm = std::max(target, 0.5 * gate_mm);
    const MountParameters step = solved - q;
    q = solved;
    AssignFaces(samples, faces, ToMount(q), gate_mm, options.edge_margin_mm, &next_face_of);
    // A lever of 20 mm (the line's half length) turns the angles' step into a displacement.
    const double moved =
        std::max(20.0 * step.head<3>().cwiseAbs().maxCoeff(), step.tail<3>().cwiseAbs().maxCoeff());
    if (gate_settled && (next_face_of == face_of || moved < kSettledMm)) break;
    if (round == options.max_rounds) {
      return FailedPrecondition("mount calibration: the points' faces did not settle in " +
                                std::to_string(round) +
                                " rounds: is the initial mount within a few mm and degrees?");
    }
    face_of.swap(next_face_of);
  }

  // The solution's residuals, Jacobian and the parameters' errors.
  MountCalibration cal;
  cal.mount = ToMount(q);
  cal.rounds = round;
  const int m = static_cast<int>(rows.size());
  cal.points = m;
  cal.points_per_face.assign(faces.size(), 0);
  for (int f : face_of) {
    if (f >= 0) ++cal.points_per_face[f];
  }
  Eigen::VectorXd r(m);
  Eigen::Matrix<double, Eigen::Dynamic, 6> jacobian(m, 6);
  const PointToPlane solution(rows);
  solution(q.data(), r.data(), jacobian.data());
  cal.rms_mm = std::sqrt(r.squaredNorm() / m);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const PlaneRow& row : rows) centroid += row.sensor_mm;
  centroid /= m;
  Eigen::Vector3d spread = Eigen::Vector3d::Zero();  // mean squares of x, y, z about the centroid
  for (const PlaneRow& row : rows) spread += (row.sensor_mm - centroid).cwiseAbs2();
  spread /= m;
  // Eq. 8's angles turn about (nearly) the sensor's y, x and z axes.
  cal.lever_mm = {std::sqrt(spread.x() + spread.z()), std::sqrt(spread.y() + spread.z()),
                  std::sqrt(spread.x() + spread.y())};
  MountParameters scale;
  scale << cal.lever_mm[0], cal.lever_mm[1], cal.lever_mm[2], 1.0, 1.0, 1.0;
  if (!(scale.head<3>().minCoeff() > 0)) {
    return FailedPrecondition(
        "mount calibration: the points used lie on one line of the sensor's frame");
  }
  const Eigen::Matrix<double, 6, 6> normal = scale.cwiseInverse().asDiagonal() *
                                             (jacobian.transpose() * jacobian) *
                                             scale.cwiseInverse().asDiagonal() / m;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eigen(normal);
  const MountParameters lambda = eigen.eigenvalues();
  const Eigen::Matrix<double, 6, 6>& v = eigen.eigenvectors();
  const double sigma = std::sqrt(r.squaredNorm() / std::max(1, m - 6));
  std::string undetermined;
  for (int j = 0; j < 6; ++j) {
    double null_share = 0, inverse = 0;
    for (int k = 0; k < 6; ++k) {
      // Numerically zero: no scan sees this combination of the parameters.
      if (!(lambda[k] > 1e-10 * lambda[5])) {
        null_share += v(j, k) * v(j, k);
      } else {
        inverse += v(j, k) * v(j, k) / lambda[k];
      }
    }
    // A parameter with a tenth of itself in the null space is unseen; one with a sliver (a
    // tilted sensor couples it weakly to an unseen one) keeps its gain from the rest.
    const bool unseen = null_share > 0.01;
    cal.error_gain[j] = unseen ? std::numeric_limits<double>::infinity() : std::sqrt(inverse);
    cal.standard_error[j] = sigma * cal.error_gain[j] / std::sqrt(m) / scale[j];
    if (unseen || !(cal.error_gain[j] <= options.max_error_gain)) {
      char text[120];
      if (unseen) {
        std::snprintf(text, sizeof(text), "%s (not seen)", kMountParameterNames[j]);
      } else {
        std::snprintf(text, sizeof(text), "%s (error gain %.3g)", kMountParameterNames[j],
                      cal.error_gain[j]);
      }
      undetermined += (undetermined.empty() ? "" : ", ") + std::string(text);
    }
  }
  if (!undetermined.empty()) {
    char limit[64];
    std::snprintf(limit, sizeof(limit), "%.3g", options.max_error_gain);
    std::string seen;
    for (size_t f = 0; f < faces.size(); ++f) {
      if (cal.points_per_face[f] == 0) continue;
      seen += (seen.empty() ? "" : ", ") + block.faces[f].name + " " +
              std::to_string(cal.points_per_face[f]);
    }
    return FailedPrecondition(
        "mount calibration: the scans leave undetermined: " + undetermined + " (points on " + seen +
        "; an error gain above " + limit +
        " magnifies the block's and the machine's errors that much). Scan across faces facing "
        "more directions (all four sides of the pyramid, in two directions) or, if the scans "
        "crossed them, start from a mount nearer the truth");
  }
  return cal;
}

}  // namespace insitu::inspect
