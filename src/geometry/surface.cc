#include "insitu/geometry/surface.h"

#include <cmath>
#include <vector>

#include <flann/flann.hpp>

#include <Eigen/Dense>

namespace insitu::geometry {

struct SurfaceModel::Impl {
  SurfaceOptions options;
  std::vector<float> xy;  // row-major n x 2, owned here: FLANN keeps a view of it
  std::vector<float> z;
  std::unique_ptr<flann::Index<flann::L2_Simple<float>>> index;
};

SurfaceModel::SurfaceModel(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SurfaceModel::~SurfaceModel() = default;
SurfaceModel::SurfaceModel(SurfaceModel&&) noexcept = default;
SurfaceModel& SurfaceModel::operator=(SurfaceModel&&) noexcept = default;

const SurfaceOptions& SurfaceModel::options() const { return impl_->options; }

Result<SurfaceModel> SurfaceModel::Build(const Cloud& cloud, const SurfaceOptions& options) {
  if (cloud.empty()) return InvalidArgument("the cloud is empty: nothing was measured to mark on");
  if (!(options.radius_mm > 0)) return InvalidArgument("surface radius_mm must be > 0");
  if (options.min_points < 3) return InvalidArgument("surface min_points must be >= 3");
  if (!(options.max_residual_mm > 0)) return InvalidArgument("surface max_residual_mm must be > 0");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->xy.reserve(2 * cloud.size());
  impl->z.reserve(cloud.size());
  for (const CloudPoint& p : cloud) {
    impl->xy.push_back(p.point_in_galvo.x());
    impl->xy.push_back(p.point_in_galvo.y());
    impl->z.push_back(p.point_in_galvo.z());
  }
  const flann::Matrix<float> data(impl->xy.data(), cloud.size(), 2);
  // Exact single kd-tree: 2D data, exact radius searches.
  impl->index = std::make_unique<flann::Index<flann::L2_Simple<float>>>(
      data, flann::KDTreeSingleIndexParams(16));
  impl->index->buildIndex();
  return SurfaceModel(std::move(impl));
}

std::optional<SurfaceSample> SurfaceModel::At(double x, double y, SurfaceMiss* miss) const {
  if (miss) *miss = SurfaceMiss::kNone;
  float q[2] = {static_cast<float>(x), static_cast<float>(y)};
  const flann::Matrix<float> query(q, 1, 2);
  std::vector<std::vector<size_t>> indices;
  std::vector<std::vector<float>> dists;
  const float r2 = static_cast<float>(impl_->options.radius_mm * impl_->options.radius_mm);
  impl_->index->radiusSearch(query, indices, dists, r2, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  const std::vector<size_t>& idx = indices[0];
  if (static_cast<int>(idx.size()) < impl_->options.min_points) {
    if (miss) *miss = SurfaceMiss::kNoPoints;
    return std::nullopt;
  }
  // The query must lie among its neighbours, not beyond them: a height is interpolated, never
  // extrapolated past the measured points by more than kReach of the radius (half a line
  // spacing of a typical scan).
  constexpr double kReach = 0.35;
  const double reach = kReach * impl_->options.radius_mm;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();  // (dx, dy, z)
  for (size_t k : idx) {
    const Eigen::Vector2d d(impl_->xy[2 * k] - x, impl_->xy[2 * k + 1] - y);
    lo = lo.cwiseMin(d);
    hi = hi.cwiseMax(d);
    mean += Eigen::Vector3d(d.x(), d.y(), impl_->z[k]);
  }
  if ((lo.array() > reach).any() || (hi.array() < -reach).any()) {
    if (miss) *miss = SurfaceMiss::kNoPoints;
    return std::nullopt;
  }
  mean /= static_cast<double>(idx.size());
  // Plane through the neighbours' centroid: slopes by least squares on centred offsets.
  // Fixed-size normal equations (accumulated; no dynamic matrices on this hot path).
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  for (size_t k : idx) {
    const Eigen::Vector2d d(impl_->xy[2 * k] - x - mean.x(), impl_->xy[2 * k + 1] - y - mean.y());
    ata += d * d.transpose();
    atb += d * (impl_->z[k] - mean.z());
  }
  // Slopes along the directions the neighbours spread in; a direction they barely spread in
  // (all on one scan line: spread under a tenth of the radius) gets slope 0 rather than a
  // slope fitted to rounding noise.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(ata);
  const double min_spread =
      std::pow(0.1 * impl_->options.radius_mm, 2) * static_cast<double>(idx.size());
  Eigen::Vector2d slope = Eigen::Vector2d::Zero();
  for (int i = 0; i < 2; ++i) {
    if (eig.eigenvalues()(i) > min_spread) {
      const Eigen::Vector2d v = eig.eigenvectors().col(i);
      slope += v * (v.dot(atb) / eig.eigenvalues()(i));
    }
  }
  double sum_sq = 0.0;
  for (size_t k : idx) {
    const Eigen::Vector2d d(impl_->xy[2 * k] - x - mean.x(), impl_->xy[2 * k + 1] - y - mean.y());
    sum_sq += std::pow(impl_->z[k] - mean.z() - slope.dot(d), 2);
  }
  const double rms = std::sqrt(sum_sq / static_cast<double>(idx.size()));
  if (rms > impl_->options.max_residual_mm) {
    if (miss) *miss = SurfaceMiss::kEdge;
    return std::nullopt;
  }
  const Eigen::Vector3d s(mean.z() - slope.dot(mean.head<2>()), slope.x(), slope.y());
  SurfaceSample out;
  out.z_mm = s(0);
  out.normal = Eigen::Vector3d(-s(1), -s(2), 1.0).normalized();
  out.points = static_cast<int>(idx.size());
  out.residual_mm = rms;
  return out;
}

}  // namespace insitu::geometry
