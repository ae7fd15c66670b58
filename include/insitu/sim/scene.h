// What the beam and the camera see: the Z-stage plate and one part standing on it.
// Parts are solids bounded by a footprint (2D signed distance, negative inside) and a top
// height above the plate (continuous or stepped): plane, step gauge, arc, triangular insert,
// and the grid plate (a chrome-on-glass reticle of "+" crosses, seed 001 sec. 3.3), whose
// reflectance carries a pattern (PartAlbedoAt).
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
  // Height of the surface at a world xy above the stage's plane (stage_z): the part's top on
  // its footprint, else the plate's top (0 on a flat plate).
  double TrueHeightAt(double x_mm, double y_mm) const;
  // True where a world xy lies on the part's footprint.
  bool OnPart(double x_mm, double y_mm) const;
  // The plate's top at a world xy above the stage's plane: its bow (StageOptions::plate_bow_mm),
  // 0 at the plate's centre.
  double PlateWarp(double x_mm, double y_mm) const {
    return plate_curvature_ * (x_mm * x_mm + y_mm * y_mm);
  }
  // How far a world xy is from the part's outline (mm, either side; infinity without a part):
  // where the part's top has a wall a ray may graze.
  double DistanceToPartEdge(double x_mm, double y_mm) const;
  // A bound on the part's highest point above the stage's plane, its seat on a bowed plate
  // included.
  double part_top_above_stage() const;
  // Reflectance of the part's top at a world xy (on the part's footprint) as a pixel sees it:
  // the part's albedo, or for the grid plate its chrome crosses on glass, weighted over the
  // pixel's footprint by a separable triangle of half-width `half_mm` (0: the point). The
  // triangle is the pixel's box convolved with itself: the cameras blur their pixel images
  // after sampling them, and a plain box there would leave the sampling's alias (a line's
  // centroid pulled toward the pixel grid by up to ~0.05 px for a 9 um line on 5 um pixels),
  // which the optics' blur before the pixels removes on a real sensor; the triangle has no
  // alias of that kind (its spectrum and slope vanish at every multiple of the pixel
  // frequency) and adds 1/12 px^2 to the blur's variance (0.91 -> 0.95 px on the coaxial
  // camera). The kernel is taken square to the part: the ~1 deg between the part and the
  // pixel grid changes its shape by a fraction of a um, not its centre.
  double PartAlbedoAt(double x_mm, double y_mm, double half_mm = 0.0) const;
  // The stage plate's reflectance at world (x, y): its own, or a label's stuck there.
  double PlateAlbedoAt(double x_mm, double y_mm) const;
  // World xy of cross (i, j) of the grid plate (i along the part's x, 0 at its centre): truth
  // for tests. The crosses are |i|, |j| <= grid_plate_crosses_per_side().
  Eigen::Vector2d GridCrossInWorld(int i, int j) const;
  int grid_plate_crosses_per_side() const;

 private:
  bool IntersectPart(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                     Hit* hit) const;
  bool InsidePart(const Eigen::Vector3d& p_local) const;
  Eigen::Vector3d ToLocal(const Eigen::Vector3d& p) const;
  // The height of the plane the part is seated on (its base) above the stage's plane at a world
  // xy.
  double BaseHeight(double x_mm, double y_mm) const;
  // The part's frame where the vertical through a world xy meets the part's top (its local z
  // is the top's there), and that point's height above the stage's plane.
  Eigen::Vector3d TopToLocal(double x_mm, double y_mm, double* height_mm) const;
  Eigen::Vector3d DirToLocal(const Eigen::Vector3d& d) const;
  Eigen::Vector3d DirToWorld(const Eigen::Vector3d& d) const;
  bool ClipToBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t0,
                 double* t1) const;

  bool IntersectBoard(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                      Hit* hit) const;
  Eigen::Vector2d BoardLocal(const Eigen::Vector3d& p) const;
  // PartAlbedoAt in the part's own frame.
  double LocalAlbedo(double x, double y, double half_mm) const;

  PartOptions part_;
  StageOptions stage_;
  BoardOptions board_;
  bool board_present_ = false;
  Eigen::Isometry3d world_from_board_ = Eigen::Isometry3d::Identity();
  std::unique_ptr<PartShape> shape_;
  double stage_z_;
  // The plate's bow as a curvature: PlateWarp = plate_curvature_ (x^2 + y^2).
  double plate_curvature_ = 0.0;
  // The part seated on the plate: its base plane is z = stage_z_ + seat_lift_ + seat_slope_ .
  // (xy - position); part_rotation_ turns the part's frame into the world's (its rotation about
  // z, then the base's tilt).
  double seat_lift_ = 0.0;
  Eigen::Vector2d seat_slope_ = Eigen::Vector2d::Zero();
  Eigen::Matrix3d part_rotation_ = Eigen::Matrix3d::Identity();
  double part_top_above_stage_ = 0.0;
};

}  // namespace insitu::sim
