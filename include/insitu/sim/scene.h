// What the beam and the camera see: the Z-stage plate and one part standing on it.
// Parts are solids bounded by a footprint (2D signed distance, negative inside) and a top
// height above the plate (continuous or stepped): plane, step gauge, arc, triangular insert.
// Ray intersection is exact to 1e-6 mm (marching + bisection), including vertical walls and
// holes, so steps shadow the beam and hide the stripe from the camera as on a real part.
// Frame: world (galvo) frame, mm.
#pragma once

#include <memory>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/sim/world_options.h"

namespace insitu::sim {

struct Hit {
  double t = 0.0;                 // distance along the (unit) ray
  Eigen::Vector3d point_in_world;
  Eigen::Vector3d normal;         // unit, facing the side the ray came from
  double albedo = 0.0;
  bool on_part = false;
  bool on_board = false;
};

// A part in its own frame: footprint centred at the origin, base at z = 0.
class PartShape {
 public:
  virtual ~PartShape() = default;
  virtual double SignedDistance2D(double x, double y) const = 0;  // < 0 inside the footprint
  virtual double Top(double x, double y) const = 0;               // height above the base
  virtual double max_height() const = 0;
  virtual Eigen::Vector2d half_extent() const = 0;                // bounding box half sizes
};

// Nullptr for kind "none".
std::unique_ptr<PartShape> MakePartShape(const PartOptions& options);

class Scene {
 public:
  Scene(const PartOptions& part, const StageOptions& stage);

  // First surface along the ray (origin, unit direction) within t_max; false if none.
  bool Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double t_max,
                 Hit* hit) const;
  // True if the part blocks the straight segment from `from` to `to` (the plate never does).
  bool Blocked(const Eigen::Vector3d& from, const Eigen::Vector3d& to) const;

  // The chessboard target at pose `index` of options.poses; index < 0 takes it away.
  void SetBoard(const BoardOptions& options, int index);
  // The board at an explicit pose [x, y, z, rx, ry, rz] (mm, deg), as BoardOptions::poses.
  void SetBoardPose(const BoardOptions& options, const std::array<double, 6>& pose);
  // Distance (mm, in the board plane) from a point on the board to the nearest edge between
  // squares: where a pixel needs supersampling to image the pattern honestly.
  double BoardEdgeDistance(const Eigen::Vector3d& point_in_world) const;
  // World position of inner corner (i, j) of the board at its current pose: for tests.
  Eigen::Vector3d BoardCornerInWorld(int i, int j) const;

  void set_stage_z(double z_mm) { stage_z_ = z_mm; }
  double stage_z() const { return stage_z_; }
  // Height of the part's top above the plate at a world xy (0 off the part): for tests.
  double TrueHeightAt(double x_mm, double y_mm) const;

 private:
  bool IntersectPart(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                     Hit* hit) const;
  bool InsidePart(const Eigen::Vector3d& p_local) const;
  Eigen::Vector3d ToLocal(const Eigen::Vector3d& p) const;
  Eigen::Vector3d DirToLocal(const Eigen::Vector3d& d) const;
  Eigen::Vector3d DirToWorld(const Eigen::Vector3d& d) const;
  bool ClipToBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t0,
                 double* t1) const;

  bool IntersectBoard(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                      Hit* hit) const;
  Eigen::Vector2d BoardLocal(const Eigen::Vector3d& p) const;

  PartOptions part_;
  StageOptions stage_;
  BoardOptions board_;
  bool board_present_ = false;
  Eigen::Isometry3d world_from_board_ = Eigen::Isometry3d::Identity();
  std::unique_ptr<PartShape> shape_;
  double stage_z_;
  double cos_rot_, sin_rot_;
};

}  // namespace insitu::sim
