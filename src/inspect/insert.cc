#include "insitu/inspect/insert.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <string>

#include <Eigen/Dense>

#include "insitu/core/robust.h"
#include "inspect/line_ends.h"

namespace insitu::inspect {

Status InsertSpec::Validate() const {
  if (!(thickness_mm > 0)) return InvalidArgument("thickness_mm must be > 0");
  if (!(edge_mm > 0)) return InvalidArgument("edge_mm must be > 0");
  if (!(hole_diameter_mm > 0 && hole_diameter_mm < 0.5 * edge_mm)) {
    return InvalidArgument("hole_diameter_mm must be > 0 and less than half edge_mm");
  }
  if (!(tip_radius_mm >= 0 && tip_radius_mm < 0.2 * edge_mm)) {
    return InvalidArgument("tip_radius_mm must be >= 0 and small against edge_mm");
  }
  if (!std::isfinite(base_z_mm)) return InvalidArgument("base_z_mm must be a number");
  if (!(gap_mm > 0)) return InvalidArgument("gap_mm must be > 0");
  if (!(inlier_mm > 0)) return InvalidArgument("inlier_mm must be > 0");
  if (!(corner_exclusion_mm >= 0 && corner_exclusion_mm < 0.3 * edge_mm)) {
    return InvalidArgument("corner_exclusion_mm must be >= 0 and under a third of edge_mm");
  }
  if (!(rake_fit_mm[0] >= 0 && rake_fit_mm[1] > rake_fit_mm[0])) {
    return InvalidArgument("rake_fit_mm must be [near, far] with 0 <= near < far");
  }
  return Status::Ok();
}

namespace {

// A line n . p = c with |n| = 1.
struct Line2 {
  Eigen::Vector2d n = Eigen::Vector2d::UnitX();
  double c = 0.0;
  double Distance(const Eigen::Vector2d& p) const { return n.dot(p) - c; }
};

// Total least squares line through points (the direction of largest spread).
Line2 FitLine(const std::vector<Eigen::Vector2d>& pts) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& p : pts) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
  Line2 l;
  l.n = es.eigenvectors().col(0);  // smallest eigenvalue: the normal
  l.c = l.n.dot(mean);
  return l;
}

bool Intersect(const Line2& a, const Line2& b, Eigen::Vector2d* p) {
  Eigen::Matrix2d m;
  m << a.n.transpose(), b.n.transpose();
  if (std::abs(m.determinant()) < 1e-6) return false;
  *p = m.inverse() * Eigen::Vector2d(a.c, b.c);
  return true;
}

// Least-squares circle: algebraic (Kasa) start, then Gauss-Newton on the geometric distance.
bool FitCircle(const std::vector<Eigen::Vector2d>& pts, Eigen::Vector2d* center, double* r) {
  if (pts.size() < 3) return false;
  Eigen::MatrixXd a(pts.size(), 3);
  Eigen::VectorXd b(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    a(i, 0) = pts[i].x();
    a(i, 1) = pts[i].y();
    a(i, 2) = 1.0;
    b(i) = pts[i].squaredNorm();
  }
  const Eigen::Vector3d s = a.colPivHouseholderQr().solve(b);
  Eigen::Vector2d c(0.5 * s(0), 0.5 * s(1));
  double radius = std::sqrt(std::max(0.0, s(2) + c.squaredNorm()));
  for (int it = 0; it < 10; ++it) {
    Eigen::MatrixXd j(pts.size(), 3);
    Eigen::VectorXd res(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector2d d = pts[i] - c;
      const double dn = std::max(d.norm(), 1e-9);
      res(i) = dn - radius;
      j(i, 0) = -d.x() / dn;
      j(i, 1) = -d.y() / dn;
      j(i, 2) = -1.0;
    }
    const Eigen::Vector3d step = (j.transpose() * j).ldlt().solve(-j.transpose() * res);
    c += step.head<2>();
    radius += step(2);
    if (step.norm() < 1e-9) break;
  }
  if (!std::isfinite(radius) || radius <= 0) return false;
  *center = c;
  *r = radius;
  return true;
}

// Up to three lines found in turn by consensus (random pairs of points, deterministic seed),
// each taking its inliers out of the pool.
std::vector<Line2> ConsensusLines(std::vector<Eigen::Vector2d> pool, double inlier_mm,
                                  double min_pair_mm, int min_inliers) {
  std::vector<Line2> lines;
  std::mt19937 rng(7);
  for (int k = 0; k < 3 && pool.size() >= 2; ++k) {
    std::uniform_int_distribution<size_t> pick(0, pool.size() - 1);
    Line2 best;
    int best_count = 0;
    for (int it = 0; it < 2000; ++it) {
      const Eigen::Vector2d& p = pool[pick(rng)];
      const Eigen::Vector2d& q = pool[pick(rng)];
      if ((q - p).norm() < min_pair_mm) continue;
      Line2 l;
      const Eigen::Vector2d d = (q - p).normalized();
      l.n = Eigen::Vector2d(-d.y(), d.x());
      l.c = l.n.dot(p);
      int count = 0;
      for (const auto& r : pool) count += std::abs(l.Distance(r)) < inlier_mm;
      if (count > best_count) {
        best_count = count;
        best = l;
      }
    }
    if (best_count < min_inliers) break;
    lines.push_back(best);
    std::vector<Eigen::Vector2d> rest;
    for (const auto& r : pool) {
      if (std::abs(best.Distance(r)) >= inlier_mm) rest.push_back(r);
    }
    pool.swap(rest);
  }
  return lines;
}

}  // namespace

Result<InsertResult> EvaluateInsert(const geometry::Cloud& cloud, const InsertSpec& s) {
  INSITU_RETURN_IF_ERROR(s.Validate());
  InsertResult r;

  // The plate: points within 0.5 mm of its nominal height (method 2 puts it within ~0.03 mm).
  std::vector<double> plate;
  for (const auto& p : cloud) {
    if (std::abs(p.point_in_galvo.z() - s.base_z_mm) < 0.5) plate.push_back(p.point_in_galvo.z());
  }
  if (plate.size() < 100) {
    return NotFound("insert: only " + std::to_string(plate.size()) +
                    " points on the plate near base_z_mm; is the scan over the stage?");
  }
  r.plate_z_mm = Median(plate);
  const double top_z = r.plate_z_mm + 0.5 * s.thickness_mm;

  std::map<int, std::vector<LinePoint>> lines;
  std::vector<LinePoint> top;
  for (const auto& p : cloud) {
    const Eigen::Vector3f& q = p.point_in_galvo;
    if (q.z() <= top_z) continue;
    lines[p.line].push_back({q.x(), q.y(), q.z(), p.intensity});
    top.push_back(lines[p.line].back());
  }
  if (top.size() < 200) {
    return NotFound("insert: only " + std::to_string(top.size()) + " points higher than " +
                    "half its thickness above the plate; is an insert in the scanned area?");
  }

  // Edge points: the ends of every run of top points along each line.
  for (auto& [index, pts] : lines) {
    SortAlongLine(&pts);
    const int n = static_cast<int>(pts.size());
    if (n < 4) continue;
    const double spacing = MedianSpacing(pts, 0, n - 1);
    std::vector<std::pair<int, int>> runs;
    int start = 0;
    for (int i = 1; i <= n; ++i) {
      if (i == n || pts[i].y - pts[i - 1].y > s.gap_mm) {
        runs.emplace_back(start, i - 1);
        start = i;
      }
    }
    const double x = pts[0].x;
    for (size_t k = 0; k < runs.size(); ++k) {
      const auto [a, b] = runs[k];
      if (b - a < 2) continue;  // a speck, not a surface
      const Eigen::Vector2d lo(x, HalfBrightnessEnd(pts, a, +1, spacing, b));
      const Eigen::Vector2d hi(x, HalfBrightnessEnd(pts, b, -1, spacing, a));
      (k == 0 ? r.outline_points : r.hole_points_mm).push_back(lo);
      (k + 1 == runs.size() ? r.outline_points : r.hole_points_mm).push_back(hi);
    }
  }

  // The edges.
  const int min_edge_points = 6;
  std::vector<Line2> edges =
      ConsensusLines(r.outline_points, s.inlier_mm, 0.3 * s.edge_mm, min_edge_points);
  if (edges.size() < 3) {
    return NotFound("insert: found " + std::to_string(edges.size()) + " of its 3 edges among " +
                    std::to_string(r.outline_points.size()) + " outline points");
  }
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (const auto& p : top) centroid += Eigen::Vector2d(p.x, p.y);
  centroid /= static_cast<double>(top.size());
  // Order the edges counterclockwise around the insert, normals pointing out.
  for (Line2& l : edges) {
    if (l.Distance(centroid) > 0) {
      l.n = -l.n;
      l.c = -l.c;
    }
  }
  std::sort(edges.begin(), edges.end(), [](const Line2& a, const Line2& b) {
    return std::atan2(a.n.y(), a.n.x()) < std::atan2(b.n.y(), b.n.x());
  });
  auto corners_of = [&](std::array<Eigen::Vector2d, 3>* corners) {
    // Corner i joins edge i and edge i + 1.
    for (int i = 0; i < 3; ++i) {
      if (!Intersect(edges[i], edges[(i + 1) % 3], &(*corners)[i])) return false;
    }
    return true;
  };
  if (!corners_of(&r.corners_mm)) return NotFound("insert: two of its edges are parallel");
  double sum_sq = 0.0;
  int count = 0;
  for (int pass = 0; pass < 3; ++pass) {
    sum_sq = 0.0;
    count = 0;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector2d& c0 = r.corners_mm[(i + 2) % 3];  // edge i runs from c0 to c1
      const Eigen::Vector2d& c1 = r.corners_mm[i];
      std::vector<Eigen::Vector2d> use;
      for (const auto& p : r.outline_points) {
        if (std::abs(edges[i].Distance(p)) >= s.inlier_mm) continue;
        if ((p - c0).norm() < s.corner_exclusion_mm || (p - c1).norm() < s.corner_exclusion_mm) {
          continue;
        }
        use.push_back(p);
      }
      if (static_cast<int>(use.size()) < min_edge_points) {
        return NotFound("insert: edge " + std::to_string(i + 1) + " has " +
                        std::to_string(use.size()) + " points away from the corners");
      }
      Line2 fitted = FitLine(use);
      if (fitted.n.dot(edges[i].n) < 0) {
        fitted.n = -fitted.n;
        fitted.c = -fitted.c;
      }
      edges[i] = fitted;
      r.edge_points[i] = static_cast<int>(use.size());
      for (const auto& p : use) sum_sq += std::pow(fitted.Distance(p), 2);
      count += static_cast<int>(use.size());
    }
    if (!corners_of(&r.corners_mm)) return NotFound("insert: two of its edges are parallel");
  }
  r.edge_fit_rms_mm = std::sqrt(sum_sq / count);
  const double correction = 2.0 * (std::sqrt(3.0) - 1.0) * s.tip_radius_mm;
  for (int i = 0; i < 3; ++i) {
    r.edge_raw_mm[i] = (r.corners_mm[i] - r.corners_mm[(i + 2) % 3]).norm();
    r.edge_mm[i] = r.edge_raw_mm[i] - correction;
  }

  // The hole: start from the median of its points, drop what is far off, fit, drop the
  // outliers beyond inlier_mm, fit again.
  if (r.hole_points_mm.size() < 8) {
    return NotFound("insert: only " + std::to_string(r.hole_points_mm.size()) +
                    " points on the hole's edge; scan with a finer line spacing");
  }
  {
    std::vector<double> hx, hy;
    for (const auto& p : r.hole_points_mm) {
      hx.push_back(p.x());
      hy.push_back(p.y());
    }
    Eigen::Vector2d c(Median(hx), Median(hy));
    std::vector<double> rr;
    for (const auto& p : r.hole_points_mm) rr.push_back((p - c).norm());
    double radius = Median(rr);
    for (double tolerance : {0.5, s.inlier_mm}) {
      std::vector<Eigen::Vector2d> use;
      for (const auto& p : r.hole_points_mm) {
        if (std::abs((p - c).norm() - radius) < tolerance) use.push_back(p);
      }
      if (use.size() < 8 || !FitCircle(use, &c, &radius)) {
        return NotFound("insert: no circle fits the hole's " + std::to_string(use.size()) +
                        " edge points");
      }
      double ss = 0;
      for (const auto& p : use) ss += std::pow((p - c).norm() - radius, 2);
      r.hole_fit_rms_mm = std::sqrt(ss / use.size());
      r.hole_points = static_cast<int>(use.size());
    }
    r.hole_center_mm = c;
    r.hole_diameter_mm = 2.0 * radius;
  }

  // The thickness: height of the rake face against the distance in from each edge, at 0.
  double thickness_sum = 0.0;
  for (int i = 0; i < 3; ++i) {
    Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
    Eigen::Vector2d atb = Eigen::Vector2d::Zero();
    int n = 0;
    for (const auto& p : top) {
      const Eigen::Vector2d q(p.x, p.y);
      const double d = -edges[i].Distance(q);  // distance in from edge i
      if (d < s.rake_fit_mm[0] || d > s.rake_fit_mm[1]) continue;
      // Only where edge i is the nearest edge by a margin (the rake bands meet at corners).
      bool clear = true;
      for (int j = 0; j < 3; ++j) {
        if (j != i && -edges[j].Distance(q) < s.rake_fit_mm[1] + s.corner_exclusion_mm) {
          clear = false;
        }
      }
      if (!clear) continue;
      ata += Eigen::Vector2d(1.0, d) * Eigen::RowVector2d(1.0, d);
      atb += Eigen::Vector2d(1.0, d) * p.z;
      ++n;
    }
    if (n < 20) {
      return NotFound("insert: only " + std::to_string(n) + " rake-face points along edge " +
                      std::to_string(i + 1));
    }
    const Eigen::Vector2d ab = ata.ldlt().solve(atb);
    r.thickness_per_edge_mm[i] = ab(0) - r.plate_z_mm;
    thickness_sum += r.thickness_per_edge_mm[i];
  }
  r.thickness_mm = thickness_sum / 3.0;
  return r;
}

}  // namespace insitu::inspect
