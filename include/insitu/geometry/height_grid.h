// The measured surface as a height field on a regular grid over the galvo xy plane, for
// projecting dense rasters (millions of pattern points) onto a large cloud. Same contract as
// SurfaceModel (surface.h): a height is a local least-squares plane through measured points,
// and where there is no such plane the answer says why and never invents a height. All numbers
// are in the galvo frame, mm.
//
// Build bins the cloud once into square cells of `cell_mm`, accumulating per cell the moments of
// a plane fit (count and the sums of x, y, z, xx, xy, yy, xz, yz, zz, in double), and turns
// them into summed-area tables. The grid nodes are the cell corners. At each node the moments of
// the SQUARE window of half-width `radius_mm` (rounded to whole cells; not the disc of
// SurfaceModel, so it holds about 4 / pi times the points of a disc of that radius) come from
// four table lookups, and the plane z = a + b (x' - x) + c (y' - y) is solved from them in O(1),
// whatever the point density: the height is a, the normal (-b, -c, 1) normalised. As in
// SurfaceModel, a direction the window's points barely spread in (under a tenth of the
// half-width, e.g. all on one scan line) gets slope 0.
//
// A node has no height (SurfaceMiss) when
//   - its window holds fewer than `min_points` points (kNoPoints: a hole, beyond the scan),
//   - one of the four half-windows (left of, right of, below or above the node) holds no point:
//     the node is not surrounded by measurements, as at the border of the scan or of a hole, and
//     a plane there would extrapolate (kNoPoints),
//   - the plane's rms residual exceeds `max_residual_mm` (kEdge: an edge between two heights in
//     the window; a mark there would be out of focus on one side).
// Sample(x, y) interpolates height and slopes bilinearly between the four nodes around (x, y),
// and only when all four have a height; else it reports kNoPoints if any of them has no points,
// kEdge otherwise. So a height is never given beyond the outermost node that is surrounded by
// measurements.
//
// Accuracy: on a surface of curvature k (1/mm) the plane of a window of half-width h is off by
// about k h^2 / 6 at the node (mean of k x^2 / 2 over the window); bilinear interpolation
// between nodes adds at most k cell^2 / 8. Noise sigma in z averages to ~sigma / sqrt(points).
// Near a step of height H the residual test lets through windows holding a fraction
// p ~ (max_residual_mm / H)^2 of the other level, biasing their height by at most
// ~max_residual_mm^2 / H.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/geometry/cloud.h"
#include "insitu/geometry/surface.h"

namespace insitu::geometry {

struct HeightGridOptions {
  double cell_mm = 0.05;         // node spacing
  double radius_mm = 0.3;        // half-width of the square fitting window, >= cell_mm
  int min_points = 6;            // in the window
  double max_residual_mm = 0.1;  // rms of the plane fit; beyond: an edge, not a surface
  // Guard against a grid that would not fit in memory (a stray far point, a cell_mm in the
  // wrong unit): building takes ~120 bytes per cell, ~500 MB at the default limit.
  int64_t max_cells = int64_t{1} << 22;

  // Ok, or invalid_argument naming the field and the allowed range.
  Status Validate() const;
};

// The points (x0_mm + c pitch_x_mm, y0_mm + r pitch_y_mm), r < rows, c < cols, row-major.
struct Raster {
  double x0_mm = 0.0;
  double y0_mm = 0.0;
  double pitch_x_mm = 0.0;
  double pitch_y_mm = 0.0;
  int rows = 0;
  int cols = 0;
};

// Heights of a Raster, row-major: index r * cols + c.
struct RasterHeights {
  int rows = 0;
  int cols = 0;
  std::vector<float> z_mm;              // NaN where there is no height
  std::vector<SurfaceMiss> miss;        // kNone where there is a height
  std::vector<Eigen::Vector3f> normal;  // unit, +z up; filled only when asked for, else empty
  int64_t valid = 0;                    // points with a height
};

class HeightGrid {
 public:
  // Errors: invalid_argument for an empty cloud, a non-finite point, bad options, or a grid of
  // more than options.max_cells cells (the message gives the size the cloud's extent needs).
  static Result<HeightGrid> Build(const Cloud& cloud, const HeightGridOptions& options);

  // The surface at (x, y), or why there is none (*miss, if given). SurfaceSample::points is the
  // fewest window points of the four nodes, residual_mm the largest rms.
  std::optional<SurfaceSample> Sample(double x_mm, double y_mm, SurfaceMiss* miss = nullptr) const;

  // Sample for every point of `raster`, into *out (its buffers are reused); the normals only
  // when `with_normals`. Same answers as Sample, to float precision (~1e-6 mm). Errors:
  // invalid_argument for negative rows or cols or a non-positive or non-finite pitch.
  Status SampleRaster(const Raster& raster, RasterHeights* out, bool with_normals = false) const;

  const HeightGridOptions& options() const { return options_; }
  // Node (i, j) lies at origin + (i, j) cell_mm, 0 <= i < nodes_x(), 0 <= j < nodes_y().
  Eigen::Vector2d origin_mm() const { return origin_mm_; }
  int nodes_x() const { return nodes_x_; }
  int nodes_y() const { return nodes_y_; }
  // The window half-width actually used: radius_mm rounded to whole cells.
  double window_half_width_mm() const { return half_cells_ * options_.cell_mm; }
  // How many nodes have a height, and why the others do not.
  int64_t valid_nodes() const { return valid_nodes_; }
  int64_t no_points_nodes() const { return no_points_nodes_; }
  int64_t edge_nodes() const { return edge_nodes_; }

 private:
  struct Node {
    double z_mm = 0.0;
    float slope_x = 0.0f;  // dz/dx
    float slope_y = 0.0f;  // dz/dy
    float rms_mm = 0.0f;
    int32_t points = 0;
    SurfaceMiss miss = SurfaceMiss::kNoPoints;
  };

  HeightGrid() = default;

  HeightGridOptions options_;
  Eigen::Vector2d origin_mm_ = Eigen::Vector2d::Zero();
  int nodes_x_ = 0;
  int nodes_y_ = 0;
  int half_cells_ = 0;
  std::vector<Node> nodes_;  // row-major: j * nodes_x_ + i
  int64_t valid_nodes_ = 0;
  int64_t no_points_nodes_ = 0;
  int64_t edge_nodes_ = 0;
};

}  // namespace insitu::geometry
