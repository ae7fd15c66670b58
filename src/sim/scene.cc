#include "insitu/sim/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

namespace insitu::sim {
namespace {

double BoxSd(double x, double y, double hx, double hy) {
  const double dx = std::abs(x) - hx, dy = std::abs(y) - hy;
  const double ox = std::max(dx, 0.0), oy = std::max(dy, 0.0);
  // sqrt, not hypot: no overflow to guard against at these sizes, and this runs at every step
  // of every ray (hypot was the profiler's largest cost in perf).
  return std::sqrt(ox * ox + oy * oy) + std::min(std::max(dx, dy), 0.0);
}

class PlaneShape : public PartShape {
 public:
  explicit PlaneShape(const PartOptions& o)
      : hx_(0.5 * o.plane_size_mm[0]), hy_(0.5 * o.plane_size_mm[1]), t_(o.plane_thickness_mm) {}
  double SignedDistance2D(double x, double y) const override { return BoxSd(x, y, hx_, hy_); }
  double Top(double, double) const override { return t_; }
  double max_height() const override { return t_; }
  Eigen::Vector2d half_extent() const override { return {hx_, hy_}; }

 private:
  double hx_, hy_, t_;
};

// The clamped skin under its maskant: clamped along x = -+size_x / 2, bowing between.
class PanelShape : public PartShape {
 public:
  explicit PanelShape(const PartOptions& o)
      : hx_(0.5 * o.panel_size_mm[0]),
        hy_(0.5 * o.panel_size_mm[1]),
        top_(o.panel_thickness_mm + o.maskant_thickness_mm),
        bow_(o.panel_bow_mm),
        holes_(o.panel_holes_mm),
        hole_r_(0.5 * o.panel_hole_diameter_mm) {}
  double SignedDistance2D(double x, double y) const override {
    double d = BoxSd(x, y, hx_, hy_);
    for (const auto& h : holes_) {
      // A hole changes the distance only nearer than hole_r_ - d to its centre.
      const double ex = x - h[0], ey = y - h[1], reach = hole_r_ - d;
      if (reach > 0 && ex * ex + ey * ey < reach * reach) {
        d = std::max(d, hole_r_ - std::sqrt(ex * ex + ey * ey));
      }
    }
    return d;
  }
  double Top(double x, double) const override {
    if (bow_ == 0.0) return top_;
    const double u = std::clamp(x / hx_, -1.0, 1.0);
    return top_ + bow_ * 0.5 * (1.0 + std::cos(M_PI * u));
  }
  double max_height() const override { return top_ + std::max(bow_, 0.0); }
  Eigen::Vector2d half_extent() const override { return {hx_, hy_}; }

 private:
  double hx_, hy_, top_, bow_;
  std::vector<std::array<double, 2>> holes_;
  double hole_r_;
};

// Steps side by side along x (first height at -x), each running the full length along y.
class StepGaugeShape : public PartShape {
 public:
  explicit StepGaugeShape(const PartOptions& o)
      : w_(o.gauge_step_width_mm), heights_(o.gauge_heights_mm) {
    hx_ = 0.5 * w_ * heights_.size();
    hy_ = 0.5 * o.gauge_length_mm;
    max_ = *std::max_element(heights_.begin(), heights_.end());
  }
  double SignedDistance2D(double x, double y) const override { return BoxSd(x, y, hx_, hy_); }
  double Top(double x, double) const override {
    int i = static_cast<int>(std::floor((x + hx_) / w_));
    i = std::clamp(i, 0, static_cast<int>(heights_.size()) - 1);
    return heights_[i];
  }
  double max_height() const override { return max_; }
  Eigen::Vector2d half_extent() const override { return {hx_, hy_}; }

 private:
  double w_, hx_, hy_, max_;
  std::vector<double> heights_;
};

// A cylindrical crown (axis along y) from edge height at x = +-w/2 to full height at x = 0.
class ArcShape : public PartShape {
 public:
  explicit ArcShape(const PartOptions& o)
      : hx_(0.5 * o.arc_width_mm), hy_(0.5 * o.arc_length_mm), h_(o.arc_height_mm) {
    const double s = o.arc_height_mm - o.arc_edge_height_mm;  // sagitta
    r_ = (hx_ * hx_ + s * s) / (2.0 * s);
    zc_ = h_ - r_;
  }
  double SignedDistance2D(double x, double y) const override { return BoxSd(x, y, hx_, hy_); }
  double Top(double x, double) const override {
    const double xc = std::min(std::abs(x), hx_);
    return zc_ + std::sqrt(r_ * r_ - xc * xc);
  }
  double max_height() const override { return h_; }
  Eigen::Vector2d half_extent() const override { return {hx_, hy_}; }

 private:
  double hx_, hy_, h_, r_, zc_;
};

// Equilateral triangle (one corner toward +y) with rounded corners, a rake band sloping
// down inward from the cutting edges, and a central through hole.
class InsertShape : public PartShape {
 public:
  explicit InsertShape(const PartOptions& o)
      : rc_(o.insert_corner_radius_mm),
        t_(o.insert_thickness_mm),
        hole_r_(0.5 * o.insert_hole_diameter_mm),
        rake_tan_(std::tan(o.insert_rake_deg * M_PI / 180.0)),
        land_(o.insert_rake_land_mm) {
    inradius_ = o.insert_edge_mm / (2.0 * std::sqrt(3.0));
    circumradius_ = 2.0 * inradius_;
  }
  double SignedDistance2D(double x, double y) const override {
    const double tri = RoundedTriangleSd(x, y);
    const double hole = hole_r_ - std::hypot(x, y);
    return std::max(tri, hole);
  }
  double Top(double x, double y) const override {
    const double depth = -RoundedTriangleSd(x, y);  // distance in from the cutting edge
    return t_ - rake_tan_ * std::clamp(depth, 0.0, land_);
  }
  double max_height() const override { return t_; }
  Eigen::Vector2d half_extent() const override { return {circumradius_, circumradius_}; }

 private:
  // Exact signed distance of the equilateral triangle shrunk by rc, minus rc: the rounded
  // triangle whose straight edges lie where the sharp triangle's do.
  double RoundedTriangleSd(double x, double y) const {
    // Half-planes of the sharp triangle: outward normals at 90, 210, 330 deg (edge facing
    // -y is at 270 deg, so the corner points to +y).
    double sd_poly = -1e300;
    const double r_in = inradius_ - rc_;  // inset triangle: same edge normals
    static constexpr double kAngles[3] = {-90.0, 30.0, 150.0};
    for (double a : kAngles) {
      const double c = std::cos(a * M_PI / 180.0), s = std::sin(a * M_PI / 180.0);
      sd_poly = std::max(sd_poly, c * x + s * y - r_in);
    }
    // Outside near a corner, the distance is to the corner point, not to the half-planes.
    double sd = sd_poly;
    if (sd_poly > 0) {
      static constexpr double kCorners[3] = {90.0, 210.0, 330.0};
      const double rv = 2.0 * r_in;
      for (double a : kCorners) {
        const double vx = rv * std::cos(a * M_PI / 180.0), vy = rv * std::sin(a * M_PI / 180.0);
        // Only when the point lies in the corner's outward wedge.
        const double ux = x - vx, uy = y - vy;
        const double nx = std::cos(a * M_PI / 180.0), ny = std::sin(a * M_PI / 180.0);
        const double along = ux * nx + uy * ny;
        const double across = std::abs(-ux * ny + uy * nx);
        if (along > 0 && across <= along * std::tan(M_PI / 3.0)) {
          sd = std::hypot(ux, uy);
        }
      }
    }
    return sd - rc_;
  }

  double rc_, t_, hole_r_, rake_tan_, land_, inradius_, circumradius_;
};

// Fraction of a triangle kernel of half-width h centred at x0 (unit area) inside [a0, a1].
double TriangleWeight(double x0, double h, double a0, double a1) {
  const auto cdf = [h](double s) {
    if (s <= -h) return 0.0;
    if (s >= h) return 1.0;
    return s <= 0.0 ? 0.5 * (s + h) * (s + h) / (h * h) : 1.0 - 0.5 * (h - s) * (h - s) / (h * h);
  };
  return cdf(a1 - x0) - cdf(a0 - x0);
}

}  // namespace

std::unique_ptr<PartShape> MakePartShape(const PartOptions& o) {
  if (o.kind == "plane") return std::make_unique<PlaneShape>(o);
  if (o.kind == "step_gauge") return std::make_unique<StepGaugeShape>(o);
  if (o.kind == "arc") return std::make_unique<ArcShape>(o);
  if (o.kind == "insert") return std::make_unique<InsertShape>(o);
  if (o.kind == "panel") return std::make_unique<PanelShape>(o);
  if (o.kind == "grid_plate") {
    // The reticle is a glass square of the given thickness: a plane part.
    PartOptions plate = o;
    plate.plane_size_mm = {o.grid_plate_size_mm, o.grid_plate_size_mm};
    plate.plane_thickness_mm = o.grid_plate_thickness_mm;
    return std::make_unique<PlaneShape>(plate);
  }
  return nullptr;
}

Scene::Scene(const PartOptions& part, const StageOptions& stage)
    : part_(part), stage_(stage), shape_(MakePartShape(part)), stage_z_(stage.z_mm) {
  const double half = 0.5 * stage.plate_size_mm;
  plate_curvature_ = -stage.plate_bow_mm / (half * half);
  const double rot = part.rotation_deg * M_PI / 180.0;
  part_rotation_ = Eigen::AngleAxisd(rot, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  part_top_above_stage_ = shape_ ? shape_->max_height() : 0.0;
  if (!shape_ || plate_curvature_ == 0.0) return;
  // A rigid part on a bowed plate rests on the plane that supports it from below. The bow is
  // quadratic, so on a dome (curvature < 0) that is the plate's tangent plane under the part's
  // centre (the part balances on the crown); in a dish (> 0) it is the tangent plane lifted by
  // the curvature times the squared reach of the footprint from its centre (it rests on its
  // farthest points: a rectangle's four corners, which a quadratic bowl puts in one plane).
  const double x0 = part.position_mm[0], y0 = part.position_mm[1];
  double reach2 = 0.0;
  if (plate_curvature_ > 0.0) {
    const Eigen::Vector2d box = shape_->half_extent();
    constexpr int kSteps = 200;
    for (int j = 0; j <= kSteps; ++j) {
      for (int i = 0; i <= kSteps; ++i) {
        const double u = box.x() * (2.0 * i / kSteps - 1.0), v = box.y() * (2.0 * j / kSteps - 1.0);
        if (shape_->SignedDistance2D(u, v) <= 0.0) reach2 = std::max(reach2, u * u + v * v);
      }
    }
  }
  seat_lift_ = PlateWarp(x0, y0) + plate_curvature_ * reach2;
  seat_slope_ = 2.0 * plate_curvature_ * Eigen::Vector2d(x0, y0);
  const Eigen::Vector2d he = shape_->half_extent();
  part_top_above_stage_ = shape_->max_height() + seat_lift_ + seat_slope_.norm() * he.norm();
  const Eigen::Vector3d base_normal =
      Eigen::Vector3d(-seat_slope_.x(), -seat_slope_.y(), 1.0).normalized();
  part_rotation_ =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), base_normal).toRotationMatrix() *
      part_rotation_;
}

Eigen::Vector3d Scene::ToLocal(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d origin(part_.position_mm[0], part_.position_mm[1], stage_z_ + seat_lift_);
  return part_rotation_.transpose() * (p - origin);
}
double Scene::BaseHeight(double x_mm, double y_mm) const {
  return seat_lift_ +
         seat_slope_.dot(Eigen::Vector2d(x_mm - part_.position_mm[0], y_mm - part_.position_mm[1]));
}
Eigen::Vector3d Scene::TopToLocal(double x_mm, double y_mm, double* height_mm) const {
  // Down the vertical through (x, y) from the base to the top: each pass moves to where the
  // top is under the last point's local xy (a tilt of a few mrad moves that xy by the height
  // change times the tilt, so three passes settle to well under a nanometre on a flat top and
  // to the top's slope times that on a curved one).
  double h = BaseHeight(x_mm, y_mm);
  Eigen::Vector3d q = ToLocal({x_mm, y_mm, stage_z_ + h});
  if (seat_slope_.isZero() && shape_) {
    // Upright (a flat plate, or a dome's crown under the part's centre): the vertical is the
    // part's own, and one look at the top is exact. The profiler's shadow march asks this at
    // every 5 um, so the passes below would cost it several times over.
    const double top = shape_->Top(q.x(), q.y());
    q.z() = top;
    if (height_mm != nullptr) *height_mm = h + top;
    return q;
  }
  for (int pass = 0; pass < 3 && shape_; ++pass) {
    h += (shape_->Top(q.x(), q.y()) - q.z()) / part_rotation_(2, 2);
    q = ToLocal({x_mm, y_mm, stage_z_ + h});
  }
  if (height_mm != nullptr) *height_mm = h;
  return q;
}
Eigen::Vector3d Scene::DirToLocal(const Eigen::Vector3d& d) const {
  return part_rotation_.transpose() * d;
}
Eigen::Vector3d Scene::DirToWorld(const Eigen::Vector3d& d) const { return part_rotation_ * d; }

bool Scene::InsidePart(const Eigen::Vector3d& q) const {
  if (q.z() < 0.0) return false;
  if (shape_->SignedDistance2D(q.x(), q.y()) > 0.0) return false;
  return q.z() <= shape_->Top(q.x(), q.y());
}

double Scene::TrueHeightAt(double x_mm, double y_mm) const {
  if (!shape_) return PlateWarp(x_mm, y_mm);
  double h = 0.0;
  const Eigen::Vector3d q = TopToLocal(x_mm, y_mm, &h);
  return shape_->SignedDistance2D(q.x(), q.y()) <= 0.0 ? h : PlateWarp(x_mm, y_mm);
}

bool Scene::OnPart(double x_mm, double y_mm) const {
  if (!shape_) return false;
  const Eigen::Vector3d q = TopToLocal(x_mm, y_mm, nullptr);
  return shape_->SignedDistance2D(q.x(), q.y()) <= 0.0;
}

double Scene::DistanceToPartEdge(double x_mm, double y_mm) const {
  if (!shape_) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d q = TopToLocal(x_mm, y_mm, nullptr);
  return std::abs(shape_->SignedDistance2D(q.x(), q.y()));
}

double Scene::part_top_above_stage() const { return part_top_above_stage_; }

int Scene::grid_plate_crosses_per_side() const {
  if (part_.kind != "grid_plate") return -1;
  const double fit = 0.5 * (part_.grid_plate_size_mm - part_.grid_plate_cross_mm);
  return static_cast<int>(std::floor(fit / part_.grid_plate_pitch_mm + 1e-9));
}

Eigen::Vector2d Scene::GridCrossInWorld(int i, int j) const {
  const double x = i * part_.grid_plate_pitch_mm, y = j * part_.grid_plate_pitch_mm;
  // On the glass's top face (the chrome), which a tilted plate moves sideways too.
  const Eigen::Vector3d r = part_rotation_ * Eigen::Vector3d(x, y, part_.grid_plate_thickness_mm);
  return {part_.position_mm[0] + r.x(), part_.position_mm[1] + r.y()};
}

double Scene::PartAlbedoAt(double x_mm, double y_mm, double half_mm) const {
  const Eigen::Vector3d q = TopToLocal(x_mm, y_mm, nullptr);
  return LocalAlbedo(q.x(), q.y(), half_mm);
}

double Scene::LocalAlbedo(double x, double y, double half) const {
  if (part_.kind != "grid_plate") return part_.albedo;
  const double p = part_.grid_plate_pitch_mm;
  const double l2 = 0.5 * part_.grid_plate_cross_mm, w2 = 0.5e-3 * part_.grid_plate_line_um;
  const int n = grid_plate_crosses_per_side();
  const double chrome = part_.grid_plate_chrome_albedo, glass = part_.grid_plate_glass_albedo;
  if (half > 2.0 * p) {
    // A footprint over many crosses sees the chrome's area fraction (two bars less their
    // shared square per cell).
    return glass + (chrome - glass) * (4.0 * l2 * w2 * 2.0 - 4.0 * w2 * w2) / (p * p);
  }
  const int i0 = static_cast<int>(std::lround(x / p)), j0 = static_cast<int>(std::lround(y / p));
  if (half <= 0.0) {
    if (std::abs(i0) > n || std::abs(j0) > n) return glass;
    const double dx = std::abs(x - i0 * p), dy = std::abs(y - j0 * p);
    const bool on = (dx <= l2 && dy <= w2) || (dx <= w2 && dy <= l2);
    return on ? chrome : glass;
  }
  // Weight of each cross inside the footprint: horizontal bar + vertical bar - their shared
  // square, each separable in x and y.
  const int k = 1 + static_cast<int>(half / p);
  double covered = 0.0;
  for (int j = std::max(-n, j0 - k); j <= std::min(n, j0 + k); ++j) {
    for (int i = std::max(-n, i0 - k); i <= std::min(n, i0 + k); ++i) {
      const double cx = i * p, cy = j * p;
      const double hx = TriangleWeight(x, half, cx - l2, cx + l2);
      const double hy = TriangleWeight(y, half, cy - w2, cy + w2);
      const double vx = TriangleWeight(x, half, cx - w2, cx + w2);
      const double vy = TriangleWeight(y, half, cy - l2, cy + l2);
      covered += hx * hy + vx * vy - vx * hy;
    }
  }
  const double fraction = std::min(1.0, covered);
  return glass + (chrome - glass) * fraction;
}

bool Scene::ClipToBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t0,
                      double* t1) const {
  const Eigen::Vector2d he = shape_->half_extent() + Eigen::Vector2d(0.01, 0.01);
  const double lo[3] = {-he.x(), -he.y(), 0.0};
  const double hi[3] = {he.x(), he.y(), shape_->max_height() + 0.01};
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-15) {
      if (o[k] < lo[k] || o[k] > hi[k]) return false;
      continue;
    }
    double a = (lo[k] - o[k]) / d[k], b = (hi[k] - o[k]) / d[k];
    if (a > b) std::swap(a, b);
    *t0 = std::max(*t0, a);
    *t1 = std::min(*t1, b);
  }
  return *t0 <= *t1;
}

bool Scene::IntersectPart(const Eigen::Vector3d& o_world, const Eigen::Vector3d& d_world,
                          double t_max, Hit* hit) const {
  if (!shape_) return false;
  const Eigen::Vector3d o = ToLocal(o_world);
  const Eigen::Vector3d d = DirToLocal(d_world);
  double t0 = 0.0, t1 = t_max;
  if (!ClipToBox(o, d, &t0, &t1)) return false;
  // March so that no step moves more than 0.05 mm sideways or 0.1 mm in height: thinner
  // features than that are below the beam size anyway.
  const double horizontal = std::hypot(d.x(), d.y());
  const double dt = std::min(horizontal > 1e-12 ? 0.05 / horizontal : 1e9,
                             std::abs(d.z()) > 1e-12 ? 0.1 / std::abs(d.z()) : 1e9);
  double prev = t0;
  if (InsidePart(o + d * t0)) {
    // Entering through the box boundary itself (ray starts inside the part's top region).
    prev = t0;
  }
  for (double t = t0; t <= t1 + dt; t += dt) {
    const double tc = std::min(t, t1);
    if (InsidePart(o + d * tc)) {
      double a = prev, b = tc;
      if (tc == t0) a = b = t0;
      for (int i = 0; i < 40 && b - a > 1e-7; ++i) {
        const double m = 0.5 * (a + b);
        (InsidePart(o + d * m) ? b : a) = m;
      }
      const Eigen::Vector3d q = o + d * b;
      const double top = shape_->Top(q.x(), q.y());
      Eigen::Vector3d n_local;
      constexpr double e = 1e-3;
      if (std::abs(q.z() - top) < 1e-4) {
        // One-sided slopes, taking the side that does not cross a step: on the very edge of a
        // step the top is flat, not a wall.
        auto slope = [&](double dx, double dy) {
          const double fwd = (shape_->Top(q.x() + dx, q.y() + dy) - top) / e;
          const double bwd = (top - shape_->Top(q.x() - dx, q.y() - dy)) / e;
          return std::abs(fwd) < std::abs(bwd) ? fwd : bwd;
        };
        n_local = Eigen::Vector3d(-slope(e, 0), -slope(0, e), 1.0).normalized();
      } else if (std::abs(shape_->SignedDistance2D(q.x(), q.y())) < 1e-3) {
        const double gx = shape_->SignedDistance2D(q.x() + e, q.y()) -
                          shape_->SignedDistance2D(q.x() - e, q.y());
        const double gy = shape_->SignedDistance2D(q.x(), q.y() + e) -
                          shape_->SignedDistance2D(q.x(), q.y() - e);
        n_local = Eigen::Vector3d(gx, gy, 0.0).normalized();
      } else {
        // A wall between two top levels: faces the lower side.
        constexpr double w = 0.02;
        const double gx = shape_->Top(q.x() + w, q.y()) - shape_->Top(q.x() - w, q.y());
        const double gy = shape_->Top(q.x(), q.y() + w) - shape_->Top(q.x(), q.y() - w);
        n_local = Eigen::Vector3d(-gx, -gy, 0.0);
        if (n_local.norm() < 1e-12) n_local = Eigen::Vector3d(-d.x(), -d.y(), 0.0);
        n_local.normalize();
      }
      if (n_local.dot(d) > 0) n_local = -n_local;
      hit->t = b;
      hit->point_in_world = o_world + d_world * b;
      hit->normal = DirToWorld(n_local);
      hit->albedo = LocalAlbedo(q.x(), q.y(), 0.0);
      hit->on_part = true;
      return true;
    }
    prev = tc;
    if (tc >= t1) break;
  }
  return false;
}

void Scene::SetBoard(const BoardOptions& options, int index) {
  board_ = options;
  board_present_ = options.present && !options.poses.empty() && index >= 0;
  if (!board_present_) return;
  SetBoardPose(options, options.poses[static_cast<size_t>(index) % options.poses.size()]);
}

void Scene::SetBoardPose(const BoardOptions& options, const std::array<double, 6>& p) {
  board_ = options;
  board_present_ = options.present;
  if (!board_present_) return;
  const double d2r = M_PI / 180.0;
  world_from_board_ = Eigen::Isometry3d::Identity();
  world_from_board_.linear() = (Eigen::AngleAxisd(p[5] * d2r, Eigen::Vector3d::UnitZ()) *
                                Eigen::AngleAxisd(p[4] * d2r, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(p[3] * d2r, Eigen::Vector3d::UnitX()))
                                   .matrix();
  world_from_board_.translation() = Eigen::Vector3d(p[0], p[1], p[2]);
}

Eigen::Vector2d Scene::BoardLocal(const Eigen::Vector3d& p) const {
  return (world_from_board_.inverse() * p).head<2>();
}

Eigen::Vector3d Scene::BoardCornerInWorld(int i, int j) const {
  const double sq = board_.square_mm;
  const Eigen::Vector3d local((i - 0.5 * (board_.inner_cols - 1)) * sq,
                              (j - 0.5 * (board_.inner_rows - 1)) * sq, 0.0);
  return world_from_board_ * local;
}

double Scene::BoardEdgeDistance(const Eigen::Vector3d& point_in_world) const {
  const Eigen::Vector2d b = BoardLocal(point_in_world);
  const double sq = board_.square_mm;
  // Edges lie at odd multiples of sq/2 from the centre when the corner count is odd, at
  // multiples of sq when even: measured from the first inner corner they are at k * sq.
  const double ox = b.x() + 0.5 * (board_.inner_cols - 1) * sq;
  const double oy = b.y() + 0.5 * (board_.inner_rows - 1) * sq;
  const double dx = std::abs(ox - sq * std::round(ox / sq));
  const double dy = std::abs(oy - sq * std::round(oy / sq));
  return std::min(dx, dy);
}

bool Scene::IntersectBoard(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                           Hit* hit) const {
  if (!board_present_) return false;
  const Eigen::Vector3d n = world_from_board_.linear().col(2);
  const double denom = n.dot(d);
  if (std::abs(denom) < 1e-12) return false;
  const double t = n.dot(world_from_board_.translation() - o) / denom;
  if (!(t > 0 && t <= t_max)) return false;
  const Eigen::Vector3d p = o + d * t;
  const Eigen::Vector2d b = BoardLocal(p);
  const double sq = board_.square_mm;
  const double half_w = 0.5 * (board_.inner_cols + 1) * sq + board_.margin_mm;
  const double half_h = 0.5 * (board_.inner_rows + 1) * sq + board_.margin_mm;
  if (std::abs(b.x()) > half_w || std::abs(b.y()) > half_h) return false;
  double albedo = board_.albedo_light;
  const double ox = b.x() + 0.5 * (board_.inner_cols + 1) * sq;
  const double oy = b.y() + 0.5 * (board_.inner_rows + 1) * sq;
  if (denom > 0) {
    albedo = 0.5;  // the back of the board
  } else if (ox >= 0 && oy >= 0 && ox < (board_.inner_cols + 1) * sq &&
             oy < (board_.inner_rows + 1) * sq) {
    const int i = static_cast<int>(ox / sq), j = static_cast<int>(oy / sq);
    if ((i + j) % 2 == 0) albedo = board_.albedo_dark;
  }
  hit->t = t;
  hit->point_in_world = p;
  hit->normal = denom < 0 ? n : Eigen::Vector3d(-n);
  hit->albedo = albedo;
  hit->on_part = false;
  hit->on_board = true;
  return true;
}

bool Scene::Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                      double t_max, Hit* hit) const {
  bool found = false;
  // The plate (an infinite plane clipped to its size).
  if (direction.z() < -1e-12) {
    // The plate's top z = stage_z + k (x^2 + y^2) along the ray: a t^2 + b t + c = 0, the
    // nearer root ahead (a flat plate: a = 0, one root).
    const double k = plate_curvature_;
    const Eigen::Vector2d o2 = origin.head<2>(), d2 = direction.head<2>();
    const double a = -k * d2.squaredNorm();
    const double b = direction.z() - 2.0 * k * o2.dot(d2);
    const double c = origin.z() - stage_z_ - k * o2.squaredNorm();
    double t = -1.0;
    if (a == 0.0) {
      t = -c / b;
    } else {
      const double disc = b * b - 4.0 * a * c;
      if (disc >= 0.0) {
        // The stable pair of roots (no cancellation between b and the root).
        const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
        const double r1 = q / a, r2 = q != 0.0 ? c / q : -1.0;
        const double lo = std::min(r1, r2), hi = std::max(r1, r2);
        t = lo > 0.0 ? lo : hi;
      }
    }
    const Eigen::Vector3d p = origin + direction * t;
    const double half = 0.5 * stage_.plate_size_mm;
    if (t > 0 && t <= t_max && std::abs(p.x()) <= half && std::abs(p.y()) <= half) {
      hit->t = t;
      hit->point_in_world = p;
      hit->normal =
          Eigen::Vector3d(-2.0 * plate_curvature_ * p.x(), -2.0 * plate_curvature_ * p.y(), 1.0)
              .normalized();
      hit->albedo = PlateAlbedoAt(p.x(), p.y());
      hit->on_part = false;
      t_max = t;
      found = true;
    }
  }
  Hit part_hit;
  if (IntersectPart(origin, direction, t_max, &part_hit)) {
    *hit = part_hit;
    t_max = part_hit.t;
    found = true;
  }
  Hit board_hit;
  if (IntersectBoard(origin, direction, t_max, &board_hit)) {
    *hit = board_hit;
    found = true;
  }
  return found;
}

double Scene::PlateAlbedoAt(double x_mm, double y_mm) const {
  double albedo = stage_.plate_albedo;
  for (const auto& l : stage_.labels) {  // the last label stuck there shows
    if (std::abs(x_mm - l[0]) <= 0.5 * l[2] && std::abs(y_mm - l[1]) <= 0.5 * l[3]) albedo = l[4];
  }
  return albedo;
}

bool Scene::Blocked(const Eigen::Vector3d& from, const Eigen::Vector3d& to) const {
  if (!shape_ && !board_present_) return false;
  const Eigen::Vector3d delta = to - from;
  const double len = delta.norm();
  const Eigen::Vector3d d = delta / len;
  // Start just off the surface so a point does not hide itself.
  constexpr double kEps = 2e-4;
  Hit h;
  return IntersectPart(from + d * kEps, d, len - kEps, &h) ||
         IntersectBoard(from + d * kEps, d, len - kEps, &h);
}

}  // namespace insitu::sim
