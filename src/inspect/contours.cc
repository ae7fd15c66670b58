#include "insitu/inspect/contours.h"

#include <Eigen/LU>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/extract_clusters.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "insitu/core/robust.h"

namespace insitu::inspect {
namespace {

pcl::PointCloud<pcl::PointXYZ>::Ptr Cloud(const Points2& points) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  cloud->reserve(points.size());
  for (const Eigen::Vector2d& p : points) {
    cloud->push_back(pcl::PointXYZ(static_cast<float>(p.x()), static_cast<float>(p.y()), 0.0f));
  }
  return cloud;
}

Eigen::Vector2d Centroid(const Points2& points) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) c += p;
  return points.empty() ? c : Eigen::Vector2d(c / static_cast<double>(points.size()));
}

// For each query point, the index of the nearest point of `to` (float precision of the search:
// ~1e-7 relative, 0.1 um on a 1 m panel, far below any groove's error).
std::vector<int> Nearest(const Points2& query, const Points2& to) {
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(Cloud(to));
  std::vector<int> out(query.size(), -1);
  std::vector<int> index(1);
  std::vector<float> d2(1);
  for (size_t i = 0; i < query.size(); ++i) {
    const pcl::PointXYZ q(static_cast<float>(query[i].x()), static_cast<float>(query[i].y()), 0.f);
    if (tree.nearestKSearch(q, 1, index, d2) == 1) out[i] = index[0];
  }
  return out;
}

// The design polyline (its points in order; closed when its ends are as close as its points)
// resampled every `step` mm, so that it is as dense as the measured points: eq. 22's rule
// takes, of the measured points claiming a design point, the farthest, which is a correction
// at a corner only when both sets are equally dense.
Points2 Resample(const Points2& polyline, double step, bool* is_closed) {
  if (polyline.size() < 2 || !(step > 0)) return polyline;
  std::vector<double> seg;
  for (size_t i = 0; i + 1 < polyline.size(); ++i) {
    seg.push_back((polyline[i + 1] - polyline[i]).norm());
  }
  Points2 chain = polyline;
  const bool closed =
      *is_closed || (polyline.back() - polyline.front()).norm() <= 1.5 * Median(seg);
  if (closed && (polyline.back() - polyline.front()).norm() > 0) chain.push_back(polyline.front());
  *is_closed = closed;
  double total = 0.0;
  for (size_t i = 0; i + 1 < chain.size(); ++i) total += (chain[i + 1] - chain[i]).norm();
  // Evenly along the chain at the step nearest `step` that divides it: a closed chain's last
  // sample one step short of its first (a sample left over at the seam would weigh the centroid
  // toward the start), an open one's at its end.
  const long n = std::max<long>(1, std::lround(total / step));
  const double even = total / static_cast<double>(n);
  const long count = closed ? n : n + 1;
  Points2 out;
  size_t i = 0;
  double start = 0.0;  // distance along the chain at chain[i]
  for (long k = 0; k < count; ++k) {
    const double s = std::min(k * even, total);
    while (i + 2 < chain.size() && start + (chain[i + 1] - chain[i]).norm() < s) {
      start += (chain[i + 1] - chain[i]).norm();
      ++i;
    }
    const Eigen::Vector2d a = chain[i], b = chain[i + 1];
    const double len = (b - a).norm();
    out.push_back(len > 0 ? Eigen::Vector2d(a + (b - a) * std::clamp((s - start) / len, 0.0, 1.0))
                          : a);
  }
  if (out.empty()) out.push_back(polyline.front());
  return out;
}

}  // namespace

std::vector<std::vector<int>> ClusterPoints(const Points2& points, double tolerance_mm,
                                            int min_points) {
  std::vector<std::vector<int>> clusters;
  if (points.empty() || !(tolerance_mm > 0)) return clusters;
  // Points that are not numbers (a profile without a groove) belong to no cluster.
  std::vector<int> finite;
  Points2 usable;
  for (size_t i = 0; i < points.size(); ++i) {
    if (points[i].allFinite()) {
      finite.push_back(static_cast<int>(i));
      usable.push_back(points[i]);
    }
  }
  if (usable.empty()) return clusters;
  const auto cloud = Cloud(usable);
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
  tree->setInputCloud(cloud);
  pcl::EuclideanClusterExtraction<pcl::PointXYZ> ec;
  ec.setClusterTolerance(tolerance_mm);
  ec.setMinClusterSize(std::max(1, min_points));
  ec.setMaxClusterSize(static_cast<int>(usable.size()));
  ec.setSearchMethod(tree);
  ec.setInputCloud(cloud);
  std::vector<pcl::PointIndices> found;
  ec.extract(found);
  for (const pcl::PointIndices& c : found) {
    std::vector<int> idx;
    for (int k : c.indices) idx.push_back(finite[k]);
    std::sort(idx.begin(), idx.end());
    clusters.push_back(std::move(idx));
  }
  // In the order of their first point: stable across runs whatever PCL's order.
  std::sort(clusters.begin(), clusters.end(),
            [](const std::vector<int>& a, const std::vector<int>& b) { return a[0] < b[0]; });
  return clusters;
}

std::vector<ContourMatch> MatchContours(const std::vector<Points2>& design,
                                        const std::vector<Points2>& measured,
                                        double max_distance_mm) {
  std::vector<ContourMatch> pairs;
  for (size_t m = 0; m < measured.size(); ++m) {
    const Eigen::Vector2d cm = Centroid(measured[m]);
    if (measured[m].empty() || !cm.allFinite()) continue;
    for (size_t d = 0; d < design.size(); ++d) {
      if (design[d].empty() || !Centroid(design[d]).allFinite()) continue;
      pairs.push_back(
          {static_cast<int>(d), static_cast<int>(m), (Centroid(design[d]) - cm).norm()});
    }
  }
  std::sort(pairs.begin(), pairs.end(), [](const ContourMatch& a, const ContourMatch& b) {
    return a.centroid_distance_mm < b.centroid_distance_mm;
  });
  std::vector<bool> design_taken(design.size(), false), measured_taken(measured.size(), false);
  std::vector<ContourMatch> out;
  for (const ContourMatch& p : pairs) {
    if (p.centroid_distance_mm > max_distance_mm) break;
    if (design_taken[p.design] || measured_taken[p.measured]) continue;
    design_taken[p.design] = measured_taken[p.measured] = true;
    out.push_back(p);
  }
  std::sort(out.begin(), out.end(),
            [](const ContourMatch& a, const ContourMatch& b) { return a.measured < b.measured; });
  return out;
}

// The foot of the perpendicular from q on a polyline (its nearest point, over every segment;
// `closed` adds the one from the last point to the first) and the polyline's unit normal there
// (left of its direction).
struct Foot {
  Eigen::Vector2d point = Eigen::Vector2d::Zero(), normal = Eigen::Vector2d::Zero();
  double distance = std::numeric_limits<double>::infinity();
  double along = 0.0;  // arc length of the foot from the polyline's first point
};
Foot FootOn(const Eigen::Vector2d& q, const Points2& line, bool closed) {
  Foot best;
  const size_t n = line.size();
  const size_t segments = closed ? n : n - 1;
  double start = 0.0;
  for (size_t i = 0; i < segments && n >= 2; ++i) {
    const Eigen::Vector2d a = line[i], b = line[(i + 1) % n], ab = b - a;
    const double len2 = ab.squaredNorm();
    if (!(len2 > 0)) continue;
    const double t = std::clamp((q - a).dot(ab) / len2, 0.0, 1.0);
    const Eigen::Vector2d f = a + t * ab;
    const double d = (q - f).norm();
    if (d < best.distance) {
      best.distance = d;
      best.point = f;
      best.normal = Eigen::Vector2d(-ab.y(), ab.x()) / std::sqrt(len2);
      best.along = start + t * std::sqrt(len2);
    }
    start += std::sqrt(len2);
  }
  return best;
}

// The contour's displacement d and scale about the design's centroid c, fitted to what the
// measured points show: their displacements across the design line,
//   (q - P) . n = d . n + s (P - c) . n,
// P the foot of the perpendicular from q on the design and n its normal there. A line profiler
// sees a groove only across it: a contour displaced along one of its sides keeps its centres at
// the stations there, so the points' own mean would see only a share of the displacement (the
// share of the contour running across it). Refitted from the feet of the points moved back by
// d, until d settles.
struct Fit {
  Eigen::Vector2d d = Eigen::Vector2d::Zero();
  double s = 0.0;             // isotropic scale
  double e1 = 0.0, e2 = 0.0;  // stretch: [[e1, e2], [e2, -e1]] (a clamped panel's bending)
  // The bending as a displacement at p (about the centroid c).
  Eigen::Vector2d Bend(const Eigen::Vector2d& p, const Eigen::Vector2d& c) const {
    const Eigen::Vector2d u = p - c;
    return {s * u.x() + e1 * u.x() + e2 * u.y(), s * u.y() + e2 * u.x() - e1 * u.y()};
  }
};
// `terms`: 5 (offset, scale, stretch), 3 (offset, scale) or 2 (offset). Returns false when the
// measured points do not determine them (a part of a contour: its sides in one direction only).
bool FitAcross(const Points2& measured, const Points2& line, bool closed, const Eigen::Vector2d& c,
               int terms, Fit* out) {
  using Vector5d = Eigen::Matrix<double, 5, 1>;
  using Matrix5d = Eigen::Matrix<double, 5, 5>;
  Fit fit;
  bool solved = false;
  for (int round = 0; round < 5; ++round) {
    Matrix5d ata = Matrix5d::Zero();
    Vector5d atb = Vector5d::Zero();
    for (const Eigen::Vector2d& q : measured) {
      const Foot f = FootOn(q - fit.d, line, closed);
      if (!std::isfinite(f.distance)) continue;
      const Eigen::Vector2d u = f.point - c, n = f.normal;
      Vector5d row;
      row << n.x(), n.y(), u.dot(n), u.x() * n.x() - u.y() * n.y(), u.y() * n.x() + u.x() * n.y();
      ata += row * row.transpose();
      atb += row * (q - f.point).dot(n);
    }
    const Eigen::MatrixXd a = ata.topLeftCorner(terms, terms);
    const Eigen::FullPivLU<Eigen::MatrixXd> lu(a);
    // Determined: full rank, and not by a hair (a contour seen along one side only).
    if (lu.rank() < terms || lu.rcond() < 1e-9) return false;
    const Eigen::VectorXd x = lu.solve(atb.head(terms));
    const bool settled = (x.head<2>() - fit.d).norm() < 1e-7;
    fit.d = x.head<2>();
    fit.s = terms >= 3 ? x(2) : 0.0;
    fit.e1 = terms >= 5 ? x(3) : 0.0;
    fit.e2 = terms >= 5 ? x(4) : 0.0;
    solved = true;
    if (settled) break;
  }
  *out = fit;
  return solved;
}

// `design`: the design resampled as densely as the measured points (eq. 21-22); `line`: the
// design as given (its own vertices, dense along curves), for distances across it. `closed`:
// the design's last point joins its first.
static Result<ContourError> CompareResampled(const Points2& design, const Points2& line,
                                             const Points2& measured, bool closed) {
  ContourError e;
  const Eigen::Vector2d c = Centroid(design);  // evenly resampled: the curve's centroid
  // Eq. 21: E = design centroid - measured centroid, the measured contour's centroid being the
  // design's moved by the displacement fitted across the line (FitAcross).
  // The fullest model the points determine: a part of a contour (a gap of missing grooves longer
  // than the clustering's tolerance splits one) may fix its offset but not its bending.
  Fit fit;
  if (FitAcross(measured, line, closed, c, 5, &fit)) {
    e.fitted = "offset, scale, stretch";
  } else if (FitAcross(measured, line, closed, c, 3, &fit)) {
    e.fitted = "offset, scale";
  } else if (FitAcross(measured, line, closed, c, 2, &fit)) {
    e.fitted = "offset";
  } else {
    return FailedPrecondition(
        "the measured points do not determine the contour's offset (they lie along one "
        "direction only)");
  }
  e.offset_mm = -fit.d;
  Points2 moved(measured);
  for (Eigen::Vector2d& q : moved) q += e.offset_mm;

  // Eq. 22: each design point's nearest measured point, corrected by the measured points that
  // take the design point for theirs (at a corner the nearest is a shortcut across it).
  const std::vector<int> from_design = Nearest(design, moved);
  const std::vector<int> from_measured = Nearest(moved, design);
  std::vector<int> claimed(design.size(), -1);  // the farthest measured point claiming each
  for (size_t k = 0; k < moved.size(); ++k) {
    const int i = from_measured[k];
    if (i < 0) continue;
    if (claimed[i] < 0 || (moved[k] - design[i]).norm() > (moved[claimed[i]] - design[i]).norm()) {
      claimed[i] = static_cast<int>(k);
    }
  }
  e.matched.resize(design.size());
  for (size_t i = 0; i < design.size(); ++i) {
    int j = from_design[i];
    const int k = claimed[i];
    if (k >= 0 && (moved[j] - design[i]).norm() < (moved[k] - design[i]).norm()) j = k;
    e.matched[i] = j;
  }

  // The bending about the design's centroid (an isotropic scale and a stretch, symmetric: a
  // rotation stays in the local error), fitted with the displacement (FitAcross): across
  // the line, since nearest points see only what moved across it (along it, a point's match
  // slides with it), and against the design as given, not its resampled chords (on a circle of
  // radius r a point reads outside a chord by its sagitta, spacing^2 / 8 r: 4 um, a 0.03 %
  // scale, at 0.5 mm on an 8 mm radius).
  const size_t n_design = design.size();
  e.scale_pct = 100.0 * fit.s;
  e.stretch_pct = 100.0 * std::hypot(fit.e1, fit.e2);
  // The local error after the bending: each matched point's distance to the design as given,
  // scaled and stretched about the centroid.
  Points2 scaled(line.size());
  for (size_t i = 0; i < line.size(); ++i) scaled[i] = line[i] + fit.Bend(line[i], c);
  double ss = 0;
  for (size_t i = 0; i < n_design; ++i) {
    const Eigen::Vector2d& q = moved[e.matched[i]];
    const double after = FootOn(q, scaled, closed).distance;
    e.local_mm.push_back((q - design[i]).norm());
    e.local_after_scale_mm.push_back(after);
    e.error_mm.push_back(e.offset_mm.norm() + e.local_mm.back());  // eq. 23
    ss += after * after;
    e.local_max_mm = std::max(e.local_max_mm, after);
  }
  e.local_rms_mm = std::sqrt(ss / static_cast<double>(design.size()));
  e.design = design;
  return e;
}

Result<ContourError> CompareContour(const Points2& design, const Points2& measured,
                                    bool closed) {
  if (design.empty() || measured.empty()) {
    return InvalidArgument(std::string("an empty ") + (design.empty() ? "design" : "measured") +
                           " contour");
  }
  for (const Points2* set : {&design, &measured}) {
    for (const Eigen::Vector2d& p : *set) {
      if (!p.allFinite()) {
        return InvalidArgument(std::string("a ") + (set == &design ? "design" : "measured") +
                               " point that is not a number");
      }
    }
  }
  // The measured centres' spacing along the line: the design's length over their number (their
  // nearest-neighbour distance would shrink with their wander across the line).
  double length = 0;
  for (size_t i = 0; i + 1 < design.size(); ++i) length += (design[i + 1] - design[i]).norm();
  if (closed) length += (design.back() - design.front()).norm();
  const double spacing = length / static_cast<double>(measured.size());
  const Points2 resampled = spacing > 0 ? Resample(design, spacing, &closed) : design;
  return CompareResampled(resampled, design, measured, closed);
}

}  // namespace insitu::inspect
