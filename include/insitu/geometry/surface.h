// The measured surface as a height field over the galvo xy plane, for placing marks on it
// (seed 000 sec. 2.4: each pattern point takes the height of the cloud points near it).
//
// A query at (x, y) gathers the cloud points within `radius_mm` in xy (a kd-tree, FLANN) and
// fits a plane z = a + b (x' - x) + c (y' - y) to them by least squares: the height is a, the
// normal (-b, -c, 1) normalised. Where fewer than `min_points` were measured nearby (a hole,
// an occluded side, beyond the scan, or all on one side of the query point, more than 0.35 of
// the radius away) there is no surface: the query says so and never invents a height. Where
// the neighbours disagree beyond `max_residual_mm` (an edge between two heights inside the
// radius) the query says that too, since a mark there would be out of focus on one side.
#pragma once

#include <memory>
#include <optional>

#include <Eigen/Core>

#include "insitu/geometry/cloud.h"

namespace insitu::geometry {

struct SurfaceOptions {
  double radius_mm = 0.3;        // a few line spacings of the scan
  int min_points = 6;
  double max_residual_mm = 0.1;  // rms of the plane fit; beyond: an edge, not a surface
};

struct SurfaceSample {
  double z_mm = 0.0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  int points = 0;
  double residual_mm = 0.0;
};

enum class SurfaceMiss { kNone, kNoPoints, kEdge };

class SurfaceModel {
 public:
  // Errors: invalid_argument for an empty cloud or bad options.
  static Result<SurfaceModel> Build(const Cloud& cloud, const SurfaceOptions& options);
  ~SurfaceModel();
  SurfaceModel(SurfaceModel&&) noexcept;
  SurfaceModel& operator=(SurfaceModel&&) noexcept;

  // The surface at (x, y), or why there is none (*miss, if given).
  std::optional<SurfaceSample> At(double x_mm, double y_mm, SurfaceMiss* miss = nullptr) const;

  const SurfaceOptions& options() const;

 private:
  struct Impl;
  explicit SurfaceModel(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::geometry
