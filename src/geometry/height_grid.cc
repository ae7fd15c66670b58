#include "insitu/geometry/height_grid.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace insitu::geometry {
namespace {

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// Plane-fit moments of a set of points: the count and the sums of x, y, z and their products.
struct Moments {
  double n = 0, x = 0, y = 0, z = 0, xx = 0, xy = 0, yy = 0, xz = 0, yz = 0, zz = 0;

  Moments& operator+=(const Moments& o) {
    n += o.n;
    x += o.x;
    y += o.y;
    z += o.z;
    xx += o.xx;
    xy += o.xy;
    yy += o.yy;
    xz += o.xz;
    yz += o.yz;
    zz += o.zz;
    return *this;
  }
  Moments& operator-=(const Moments& o) {
    n -= o.n;
    x -= o.x;
    y -= o.y;
    z -= o.z;
    xx -= o.xx;
    xy -= o.xy;
    yy -= o.yy;
    xz -= o.xz;
    yz -= o.yz;
    zz -= o.zz;
    return *this;
  }
};

// Sum over the cells [i0, i1) x [j0, j1) from a summed-area table whose entry (i, j), at
// j * stride + i, holds the sum over the cells [0, i) x [0, j).
template <typename T>
T RectSum(const std::vector<T>& sat, int stride, int i0, int j0, int i1, int j1) {
  T s = sat[static_cast<size_t>(j1) * stride + i1];
  s -= sat[static_cast<size_t>(j0) * stride + i1];
  s -= sat[static_cast<size_t>(j1) * stride + i0];
  s += sat[static_cast<size_t>(j0) * stride + i0];
  return s;
}

// Which miss the four nodes around a query add up to: none if all have a height, no points if
// any lacks points, else an edge.
template <typename NodeT>
SurfaceMiss CombinedMiss(const NodeT& a, const NodeT& b, const NodeT& c, const NodeT& d) {
  if (a.miss == SurfaceMiss::kNone && b.miss == SurfaceMiss::kNone &&
      c.miss == SurfaceMiss::kNone && d.miss == SurfaceMiss::kNone) {
    return SurfaceMiss::kNone;
  }
  if (a.miss == SurfaceMiss::kNoPoints || b.miss == SurfaceMiss::kNoPoints ||
      c.miss == SurfaceMiss::kNoPoints || d.miss == SurfaceMiss::kNoPoints) {
    return SurfaceMiss::kNoPoints;
  }
  return SurfaceMiss::kEdge;
}

// Position along one axis in node units -> the lower node and the weight of the upper one, or
// a lower node of -1 outside [0, nodes - 1] (and for NaN).
void Locate(double u, int nodes, int* lower, double* f) {
  if (!(u >= 0.0 && u <= nodes - 1)) {
    *lower = -1;
    *f = 0.0;
    return;
  }
  *lower = std::min(static_cast<int>(u), nodes - 2);
  *f = u - *lower;
}

}  // namespace

Status HeightGridOptions::Validate() const {
  if (!(cell_mm > 0) || !std::isfinite(cell_mm)) {
    return InvalidArgument("height grid cell_mm must be > 0, got " + Num(cell_mm));
  }
  if (!(radius_mm > 0) || !std::isfinite(radius_mm)) {
    return InvalidArgument("height grid radius_mm must be > 0, got " + Num(radius_mm));
  }
  if (radius_mm < cell_mm) {
    return InvalidArgument("height grid radius_mm (" + Num(radius_mm) + ") must be >= cell_mm (" +
                           Num(cell_mm) + "): the fitting window is made of whole cells");
  }
  if (min_points < 3) {
    return InvalidArgument("height grid min_points must be >= 3 (a plane), got " +
                           std::to_string(min_points));
  }
  if (!(max_residual_mm > 0)) {
    return InvalidArgument("height grid max_residual_mm must be > 0, got " + Num(max_residual_mm));
  }
  if (max_cells < 1) {
    return InvalidArgument("height grid max_cells must be >= 1, got " + std::to_string(max_cells));
  }
  return Status::Ok();
}

Result<HeightGrid> HeightGrid::Build(const Cloud& cloud, const HeightGridOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  if (cloud.empty()) return InvalidArgument("the cloud is empty: nothing was measured to mark on");
  if (cloud.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
    return InvalidArgument("the cloud has " + std::to_string(cloud.size()) +
                           " points, more than a height grid counts (2^31 - 1)");
  }
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  double z_sum = 0.0;
  for (size_t k = 0; k < cloud.size(); ++k) {
    const Eigen::Vector3d p = cloud[k].point_in_galvo.cast<double>();
    if (!p.allFinite()) {
      return InvalidArgument("cloud point " + std::to_string(k) + " is not finite");
    }
    lo = lo.cwiseMin(p.head<2>());
    hi = hi.cwiseMax(p.head<2>());
    z_sum += p.z();
  }
  const double cell = options.cell_mm;
  const Eigen::Vector2d extent = hi - lo;
  const double cells_x = std::floor(extent.x() / cell) + 1.0;
  const double cells_y = std::floor(extent.y() / cell) + 1.0;
  if (cells_x * cells_y > static_cast<double>(options.max_cells)) {
    return InvalidArgument(
        "a height grid of cell_mm " + Num(cell) + " over the cloud's " + Num(extent.x()) + " x " +
        Num(extent.y()) + " mm would have " + Num(cells_x) + " x " + Num(cells_y) + " = " +
        Num(cells_x * cells_y) + " cells (~" + Num(std::round(cells_x * cells_y * 120e-6)) +
        " MB), more than max_cells " + std::to_string(options.max_cells) +
        ": use a larger cell_mm, or crop the cloud (a stray far point widens it)");
  }

  HeightGrid grid;
  grid.options_ = options;
  grid.origin_mm_ = lo;
  const int nx = static_cast<int>(cells_x);
  const int ny = static_cast<int>(cells_y);
  grid.nodes_x_ = nx + 1;
  grid.nodes_y_ = ny + 1;
  const int w = std::max(1, static_cast<int>(std::lround(options.radius_mm / cell)));
  grid.half_cells_ = w;

  // Summed-area tables over the cells; entry (i, j) sums the cells [0, i) x [0, j), so it has
  // one more row and column than there are cells, as many as there are nodes.
  const int stride = nx + 1;
  const size_t table_size = static_cast<size_t>(nx + 1) * static_cast<size_t>(ny + 1);
  std::vector<Moments> moments(table_size);
  std::vector<int32_t> counts(table_size, 0);
  auto at = [stride](int i, int j) { return static_cast<size_t>(j) * stride + i; };

  // Each point into its cell, relative to the cell's centre and to the cloud's mean height:
  // the per-cell sums stay as small as the cell, whatever the part's position and height.
  const double z_ref = z_sum / static_cast<double>(cloud.size());
  for (const CloudPoint& cp : cloud) {
    const double x = cp.point_in_galvo.x(), y = cp.point_in_galvo.y();
    const int ci = std::clamp(static_cast<int>((x - lo.x()) / cell), 0, nx - 1);
    const int cj = std::clamp(static_cast<int>((y - lo.y()) / cell), 0, ny - 1);
    const double dx = x - (lo.x() + (ci + 0.5) * cell);
    const double dy = y - (lo.y() + (cj + 0.5) * cell);
    const double dz = cp.point_in_galvo.z() - z_ref;
    Moments d;
    d.n = 1.0;
    d.x = dx;
    d.y = dy;
    d.z = dz;
    d.xx = dx * dx;
    d.xy = dx * dy;
    d.yy = dy * dy;
    d.xz = dx * dz;
    d.yz = dy * dz;
    d.zz = dz * dz;
    moments[at(ci + 1, cj + 1)] += d;
    ++counts[at(ci + 1, cj + 1)];
  }
  // Summed-area tables add cells up, so they need one origin for all cells: the grid's centre
  // (each cell's sums shifted exactly from its own centre), which halves the largest coordinate.
  // Precision: a table entry reaches ~N X^2 (N points, |X| <= half the extent), so a window sum
  // taken from four entries carries ~1e-16 N X^2 of rounding: 1e-16 * 1e6 * 400 = 4e-8 mm^2 for
  // a million points over 40 mm. Against centred window moments of n h^2 / 3 = 7 mm^2 (225
  // points, h = 0.3 mm) that is ~1e-8 relative in the slopes; in zz, against the noise
  // n sigma^2 = 0.02 mm^2 (sigma 0.01 mm), ~1e-8 mm in the rms.
  for (int cj = 0; cj < ny; ++cj) {
    const double cy = (cj + 0.5 - 0.5 * ny) * cell;
    for (int ci = 0; ci < nx; ++ci) {
      const double cx = (ci + 0.5 - 0.5 * nx) * cell;
      Moments& m = moments[at(ci + 1, cj + 1)];
      const Moments l = m;
      m.x = l.x + l.n * cx;
      m.y = l.y + l.n * cy;
      m.xx = l.xx + 2.0 * cx * l.x + l.n * cx * cx;
      m.xy = l.xy + cx * l.y + cy * l.x + l.n * cx * cy;
      m.yy = l.yy + 2.0 * cy * l.y + l.n * cy * cy;
      m.xz = l.xz + cx * l.z;
      m.yz = l.yz + cy * l.z;
    }
  }
  for (int j = 1; j <= ny; ++j) {
    for (int i = 1; i <= nx; ++i) {
      moments[at(i, j)] += moments[at(i - 1, j)];
      counts[at(i, j)] += counts[at(i - 1, j)];
    }
    for (int i = 1; i <= nx; ++i) {
      moments[at(i, j)] += moments[at(i, j - 1)];
      counts[at(i, j)] += counts[at(i, j - 1)];
    }
  }

  // Slopes only along directions the points spread in by more than a tenth of the half-width
  // (as SurfaceModel does with its radius).
  const double h = w * cell;
  const double min_spread_per_point = 0.01 * h * h;
  grid.nodes_.resize(table_size);
  for (int j = 0; j <= ny; ++j) {
    const int j0 = std::max(j - w, 0), j1 = std::min(j + w, ny);
    const double py = (j - 0.5 * ny) * cell;
    for (int i = 0; i <= nx; ++i) {
      const int i0 = std::max(i - w, 0), i1 = std::min(i + w, nx);
      Node& node = grid.nodes_[at(i, j)];
      node.points = RectSum(counts, stride, i0, j0, i1, j1);
      if (node.points < options.min_points || RectSum(counts, stride, i0, j0, i, j1) == 0 ||
          RectSum(counts, stride, i, j0, i1, j1) == 0 ||
          RectSum(counts, stride, i0, j0, i1, j) == 0 ||
          RectSum(counts, stride, i0, j, i1, j1) == 0) {
        node.miss = SurfaceMiss::kNoPoints;
        ++grid.no_points_nodes_;
        continue;
      }
      const Moments m = RectSum(moments, stride, i0, j0, i1, j1);
      const double px = (i - 0.5 * nx) * cell;
      // Plane through the centroid, slopes from the centred moments.
      const double n = m.n;
      const double mx = m.x / n, my = m.y / n, mz = m.z / n;
      const double cxx = m.xx - m.x * mx, cxy = m.xy - m.x * my, cyy = m.yy - m.y * my;
      const double cxz = m.xz - m.x * mz, cyz = m.yz - m.y * mz, czz = m.zz - m.z * mz;
      // Eigenvalues of the 2 x 2 spread [cxx cxy; cxy cyy], closed form.
      const double half_trace = 0.5 * (cxx + cyy);
      const double root = std::hypot(0.5 * (cxx - cyy), cxy);
      const double l_big = half_trace + root, l_small = half_trace - root;
      const double min_spread = min_spread_per_point * n;
      double gx = 0.0, gy = 0.0;
      if (l_small > min_spread) {
        const double det = cxx * cyy - cxy * cxy;
        gx = (cyy * cxz - cxy * cyz) / det;
        gy = (cxx * cyz - cxy * cxz) / det;
      } else if (l_big > min_spread) {
        // Along the one direction of spread only. Two forms of its eigenvector; the longer
        // one is the well-conditioned one.
        Eigen::Vector2d v(l_big - cyy, cxy);
        const Eigen::Vector2d v2(cxy, l_big - cxx);
        if (v2.squaredNorm() > v.squaredNorm()) v = v2;
        v.normalize();
        const double s = (v.x() * cxz + v.y() * cyz) / l_big;
        gx = s * v.x();
        gy = s * v.y();
      }
      const double rss =
          czz - 2.0 * (gx * cxz + gy * cyz) + (gx * gx * cxx + 2.0 * gx * gy * cxy + gy * gy * cyy);
      const double rms = std::sqrt(std::max(rss, 0.0) / n);
      node.z_mm = z_ref + mz + gx * (px - mx) + gy * (py - my);
      node.slope_x = static_cast<float>(gx);
      node.slope_y = static_cast<float>(gy);
      node.rms_mm = static_cast<float>(rms);
      if (rms > options.max_residual_mm) {
        node.miss = SurfaceMiss::kEdge;
        ++grid.edge_nodes_;
      } else {
        node.miss = SurfaceMiss::kNone;
        ++grid.valid_nodes_;
      }
    }
  }
  return grid;
}

std::optional<SurfaceSample> HeightGrid::Sample(double x_mm, double y_mm, SurfaceMiss* miss) const {
  if (miss) *miss = SurfaceMiss::kNoPoints;
  int i = -1, j = -1;
  double fx = 0.0, fy = 0.0;
  Locate((x_mm - origin_mm_.x()) / options_.cell_mm, nodes_x_, &i, &fx);
  Locate((y_mm - origin_mm_.y()) / options_.cell_mm, nodes_y_, &j, &fy);
  if (i < 0 || j < 0) return std::nullopt;
  const size_t k = static_cast<size_t>(j) * nodes_x_ + i;
  const Node& n00 = nodes_[k];
  const Node& n10 = nodes_[k + 1];
  const Node& n01 = nodes_[k + nodes_x_];
  const Node& n11 = nodes_[k + nodes_x_ + 1];
  const SurfaceMiss m = CombinedMiss(n00, n10, n01, n11);
  if (miss) *miss = m;
  if (m != SurfaceMiss::kNone) return std::nullopt;
  const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  SurfaceSample out;
  out.z_mm = w00 * n00.z_mm + w10 * n10.z_mm + w01 * n01.z_mm + w11 * n11.z_mm;
  const double gx = w00 * n00.slope_x + w10 * n10.slope_x + w01 * n01.slope_x + w11 * n11.slope_x;
  const double gy = w00 * n00.slope_y + w10 * n10.slope_y + w01 * n01.slope_y + w11 * n11.slope_y;
  out.normal = Eigen::Vector3d(-gx, -gy, 1.0).normalized();
  out.points = std::min({n00.points, n10.points, n01.points, n11.points});
  out.residual_mm = std::max({n00.rms_mm, n10.rms_mm, n01.rms_mm, n11.rms_mm});
  return out;
}

Status HeightGrid::SampleRaster(const Raster& raster, RasterHeights* out, bool with_normals) const {
  if (raster.rows < 0 || raster.cols < 0) {
    return InvalidArgument("raster rows and cols must be >= 0, got " + std::to_string(raster.rows) +
                           " x " + std::to_string(raster.cols));
  }
  if (!(raster.pitch_x_mm > 0) || !(raster.pitch_y_mm > 0) || !std::isfinite(raster.pitch_x_mm) ||
      !std::isfinite(raster.pitch_y_mm)) {
    return InvalidArgument("raster pitch_x_mm and pitch_y_mm must be finite and > 0, got " +
                           Num(raster.pitch_x_mm) + ", " + Num(raster.pitch_y_mm));
  }
  const size_t total = static_cast<size_t>(raster.rows) * static_cast<size_t>(raster.cols);
  out->rows = raster.rows;
  out->cols = raster.cols;
  out->z_mm.resize(total);
  out->miss.resize(total);
  out->normal.resize(with_normals ? total : 0);
  out->valid = 0;

  // Every row shares the columns' nodes and weights: locate them once.
  std::vector<int> col_node(raster.cols);
  std::vector<double> col_f(raster.cols);
  for (int c = 0; c < raster.cols; ++c) {
    const double x = raster.x0_mm + c * raster.pitch_x_mm;
    Locate((x - origin_mm_.x()) / options_.cell_mm, nodes_x_, &col_node[c], &col_f[c]);
  }
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  int64_t valid = 0;
  for (int r = 0; r < raster.rows; ++r) {
    const size_t row = static_cast<size_t>(r) * raster.cols;
    const double y = raster.y0_mm + r * raster.pitch_y_mm;
    int j = -1;
    double fy = 0.0;
    Locate((y - origin_mm_.y()) / options_.cell_mm, nodes_y_, &j, &fy);
    if (j < 0) {
      std::fill_n(out->z_mm.begin() + row, raster.cols, kNan);
      std::fill_n(out->miss.begin() + row, raster.cols, SurfaceMiss::kNoPoints);
      if (with_normals) {
        std::fill_n(out->normal.begin() + row, raster.cols, Eigen::Vector3f::Constant(kNan));
      }
      continue;
    }
    const Node* lower = &nodes_[static_cast<size_t>(j) * nodes_x_];
    const Node* upper = lower + nodes_x_;
    for (int c = 0; c < raster.cols; ++c) {
      const int i = col_node[c];
      SurfaceMiss m = SurfaceMiss::kNoPoints;
      if (i >= 0) m = CombinedMiss(lower[i], lower[i + 1], upper[i], upper[i + 1]);
      out->miss[row + c] = m;
      if (m != SurfaceMiss::kNone) {
        out->z_mm[row + c] = kNan;
        if (with_normals) out->normal[row + c] = Eigen::Vector3f::Constant(kNan);
        continue;
      }
      ++valid;
      const double fx = col_f[c];
      const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy,
                   w11 = fx * fy;
      out->z_mm[row + c] = static_cast<float>(w00 * lower[i].z_mm + w10 * lower[i + 1].z_mm +
                                              w01 * upper[i].z_mm + w11 * upper[i + 1].z_mm);
      if (with_normals) {
        const double gx = w00 * lower[i].slope_x + w10 * lower[i + 1].slope_x +
                          w01 * upper[i].slope_x + w11 * upper[i + 1].slope_x;
        const double gy = w00 * lower[i].slope_y + w10 * lower[i + 1].slope_y +
                          w01 * upper[i].slope_y + w11 * upper[i + 1].slope_y;
        out->normal[row + c] =
            Eigen::Vector3f(static_cast<float>(-gx), static_cast<float>(-gy), 1.0f).normalized();
      }
    }
  }
  out->valid = valid;
  return Status::Ok();
}

}  // namespace insitu::geometry
