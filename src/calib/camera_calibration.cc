#include "insitu/calib/camera_calibration.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

namespace insitu::calib {
namespace {

cv::Matx33d CameraMatrix(const CameraIntrinsics& c) {
  return cv::Matx33d(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
}
cv::Mat Distortion(const CameraIntrinsics& c) {
  return (cv::Mat_<double>(1, 5) << c.k1, c.k2, c.p1, c.p2, c.k3);
}

}  // namespace

Status IntrinsicsOptions::Validate() const {
  if (min_views < 3) return InvalidArgument("min_views must be >= 3, got " + std::to_string(min_views));
  if (!(min_coverage >= 0 && min_coverage <= 1)) return InvalidArgument("min_coverage must be in [0, 1]");
  if (!(max_rms_px > 0)) return InvalidArgument("max_rms_px must be > 0");
  return Status::Ok();
}

IntrinsicsSummary CalibrateIntrinsics(const std::vector<std::vector<Eigen::Vector2d>>& corners,
                                      const BoardGeometry& board, int width, int height,
                                      const IntrinsicsOptions& options) {
  IntrinsicsSummary s;
  const Status valid = options.Validate();
  if (!valid.ok()) {
    s.message = valid.message();
    return s;
  }
  const size_t per_view = static_cast<size_t>(board.inner_cols * board.inner_rows);
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  std::set<int> cells;
  constexpr int kGrid = 16;
  for (const auto& view : corners) {
    if (view.size() != per_view) continue;
    std::vector<cv::Point3f> obj;
    std::vector<cv::Point2f> img;
    for (int j = 0; j < board.inner_rows; ++j) {
      for (int i = 0; i < board.inner_cols; ++i) {
        obj.emplace_back(static_cast<float>(i * board.square_mm),
                         static_cast<float>(j * board.square_mm), 0.0f);
        const Eigen::Vector2d& p = view[static_cast<size_t>(j * board.inner_cols + i)];
        img.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
        const int cx = std::clamp(static_cast<int>(p.x() * kGrid / width), 0, kGrid - 1);
        const int cy = std::clamp(static_cast<int>(p.y() * kGrid / height), 0, kGrid - 1);
        cells.insert(cy * kGrid + cx);
      }
    }
    object.push_back(std::move(obj));
    image.push_back(std::move(img));
  }
  s.views = static_cast<int>(object.size());
  s.coverage = static_cast<double>(cells.size()) / (kGrid * kGrid);
  if (s.views < options.min_views) {
    s.message = "too few views: the board was found in " + std::to_string(s.views) +
                " frames, at least " + std::to_string(options.min_views) + " are needed";
    return s;
  }
  if (s.coverage < options.min_coverage) {
    s.message = "poor coverage: corners cover " + std::to_string(static_cast<int>(100 * s.coverage)) +
                " % of the image, at least " +
                std::to_string(static_cast<int>(100 * options.min_coverage)) +
                " % is needed; show the board near the image edges and corners";
    return s;
  }
  cv::Mat k, dist;
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat std_intr, std_extr, per_view_errors;
  int flags = options.fix_k3 ? cv::CALIB_FIX_K3 : 0;
  try {
    s.rms_px = cv::calibrateCamera(object, image, cv::Size(width, height), k, dist, rvecs, tvecs,
                                   std_intr, std_extr, per_view_errors, flags,
                                   cv::TermCriteria(cv::TermCriteria::COUNT |
                                                        cv::TermCriteria::EPS, 100, 1e-12));
  } catch (const cv::Exception& e) {
    s.message = std::string("calibration did not converge: ") + e.what();
    return s;
  }
  for (int i = 0; i < per_view_errors.rows; ++i) s.view_rms_px.push_back(per_view_errors.at<double>(i));
  for (int i = 0; i < std::min(8, std_intr.rows); ++i) s.stddev.push_back(std_intr.at<double>(i));
  s.intrinsics.width_px = width;
  s.intrinsics.height_px = height;
  s.intrinsics.fx = k.at<double>(0, 0);
  s.intrinsics.fy = k.at<double>(1, 1);
  s.intrinsics.cx = k.at<double>(0, 2);
  s.intrinsics.cy = k.at<double>(1, 2);
  s.intrinsics.k1 = dist.at<double>(0);
  s.intrinsics.k2 = dist.at<double>(1);
  s.intrinsics.p1 = dist.at<double>(2);
  s.intrinsics.p2 = dist.at<double>(3);
  s.intrinsics.k3 = dist.at<double>(4);
  if (!std::isfinite(s.rms_px) || s.rms_px > options.max_rms_px) {
    s.message = "reprojection RMS " + std::to_string(s.rms_px) + " px exceeds " +
                std::to_string(options.max_rms_px) + " px";
    return s;
  }
  s.ok = true;
  s.message = "ok";
  return s;
}

Status AlignmentOptions::Validate() const {
  if (min_spots < 4) return InvalidArgument("min_spots must be >= 4");
  if (!(min_spread_mm > 0)) return InvalidArgument("min_spread_mm must be > 0");
  if (!(max_rms_mm > 0)) return InvalidArgument("max_rms_mm must be > 0");
  return Status::Ok();
}

AlignmentSummary AlignCameraToGalvo(const std::vector<GalvoSpot>& spots,
                                    const CameraIntrinsics& camera,
                                    const AlignmentOptions& options) {
  AlignmentSummary s;
  s.spots = static_cast<int>(spots.size());
  const Status valid = options.Validate();
  if (!valid.ok()) {
    s.message = valid.message();
    return s;
  }
  if (s.spots < options.min_spots) {
    s.message = "too few pointer spots: " + std::to_string(s.spots) + " found, at least " +
                std::to_string(options.min_spots) + " are needed";
    return s;
  }
  // Singular geometry: spots on (nearly) one line fix no rotation about it.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const GalvoSpot& g : spots) mean += g.commanded_in_galvo;
  mean /= spots.size();
  Eigen::MatrixXd centred(spots.size(), 3);
  for (size_t i = 0; i < spots.size(); ++i) centred.row(i) = (spots[i].commanded_in_galvo - mean).transpose();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(centred);
  const double spread = svd.singularValues()(1) / std::sqrt(static_cast<double>(spots.size()));
  if (spread < options.min_spread_mm / 4.0) {
    s.message = "singular geometry: the spots lie nearly on one line (spread " +
                std::to_string(spread) + " mm across it)";
    return s;
  }
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (const GalvoSpot& g : spots) {
    obj.emplace_back(g.commanded_in_galvo.x(), g.commanded_in_galvo.y(), g.commanded_in_galvo.z());
    img.emplace_back(g.pixel.x(), g.pixel.y());
  }
  cv::Mat rvec, tvec;
  try {
    if (!cv::solvePnP(obj, img, CameraMatrix(camera), Distortion(camera), rvec, tvec, false,
                      cv::SOLVEPNP_ITERATIVE)) {
      s.message = "pose could not be solved from the spots";
      return s;
    }
    cv::solvePnPRefineLM(obj, img, CameraMatrix(camera), Distortion(camera), rvec, tvec);
  } catch (const cv::Exception& e) {
    s.message = std::string("pose could not be solved: ") + e.what();
    return s;
  }
  const Eigen::Vector3d rv(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
  s.camera_from_galvo = Eigen::Isometry3d::Identity();
  if (rv.norm() > 0) s.camera_from_galvo.linear() = Eigen::AngleAxisd(rv.norm(), rv.normalized()).matrix();
  s.camera_from_galvo.translation() = Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  // Residuals: pixel reprojection, and in mm where each spot's ray meets its own height.
  const Eigen::Isometry3d galvo_from_camera = s.camera_from_galvo.inverse();
  std::vector<Eigen::Vector2d> pixels;
  for (const GalvoSpot& g : spots) pixels.push_back(g.pixel);
  const std::vector<Eigen::Vector2d> rays = camera.Undistort(pixels);
  double sum_px = 0, sum_mm = 0;
  for (size_t i = 0; i < spots.size(); ++i) {
    const Eigen::Vector2d proj = camera.Project(s.camera_from_galvo * spots[i].commanded_in_galvo);
    sum_px += (proj - spots[i].pixel).squaredNorm();
    const Eigen::Vector3d origin = galvo_from_camera.translation();
    const Eigen::Vector3d dir = galvo_from_camera.linear() * Eigen::Vector3d(rays[i].x(), rays[i].y(), 1.0);
    const double t = (spots[i].commanded_in_galvo.z() - origin.z()) / dir.z();
    const Eigen::Vector3d hit = origin + t * dir;
    const double e = (hit - spots[i].commanded_in_galvo).head<2>().norm();
    sum_mm += e * e;
    s.max_mm = std::max(s.max_mm, e);
  }
  s.rms_px = std::sqrt(sum_px / spots.size());
  s.rms_mm = std::sqrt(sum_mm / spots.size());
  if (s.rms_mm > options.max_rms_mm) {
    s.message = "spot residual " + std::to_string(s.rms_mm) + " mm rms exceeds " +
                std::to_string(options.max_rms_mm) + " mm";
    return s;
  }
  s.ok = true;
  s.message = "ok";
  return s;
}

PlatePoseSummary PlateFromBoard(const std::vector<Eigen::Vector2d>& corners,
                                const BoardGeometry& board, const CameraIntrinsics& camera,
                                double thickness_mm) {
  PlatePoseSummary s;
  const size_t expected = static_cast<size_t>(board.inner_cols) * board.inner_rows;
  if (corners.size() != expected) {
    s.message = "the board on the plate shows " + std::to_string(corners.size()) +
                " corners, expected " + std::to_string(expected);
    return s;
  }
  if (!(thickness_mm >= 0)) {
    s.message = "board thickness must be >= 0 mm";
    return s;
  }
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (int j = 0; j < board.inner_rows; ++j) {
    for (int i = 0; i < board.inner_cols; ++i) {
      obj.emplace_back(i * board.square_mm, j * board.square_mm, 0.0);
      const Eigen::Vector2d& p = corners[static_cast<size_t>(j) * board.inner_cols + i];
      img.emplace_back(p.x(), p.y());
    }
  }
  cv::Mat rvec, tvec;
  try {
    if (!cv::solvePnP(obj, img, CameraMatrix(camera), Distortion(camera), rvec, tvec, false,
                      cv::SOLVEPNP_IPPE)) {
      s.message = "the board's pose could not be solved";
      return s;
    }
    cv::solvePnPRefineLM(obj, img, CameraMatrix(camera), Distortion(camera), rvec, tvec);
  } catch (const cv::Exception& e) {
    s.message = std::string("the board's pose could not be solved: ") + e.what();
    return s;
  }
  const Eigen::Vector3d rv(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
  Eigen::Isometry3d camera_from_board = Eigen::Isometry3d::Identity();
  if (rv.norm() > 0) camera_from_board.linear() = Eigen::AngleAxisd(rv.norm(), rv.normalized()).matrix();
  camera_from_board.translation() = Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  double sum = 0;
  for (size_t k = 0; k < obj.size(); ++k) {
    const Eigen::Vector2d proj =
        camera.Project(camera_from_board * Eigen::Vector3d(obj[k].x, obj[k].y, obj[k].z));
    sum += (proj - Eigen::Vector2d(img[k].x, img[k].y)).squaredNorm();
  }
  s.rms_px = std::sqrt(sum / obj.size());
  // The board's z may point into the plate or out of it (the corner order decides): the
  // plate frame's +z faces the camera, and its x, y stay right-handed with it.
  Eigen::Isometry3d board_from_plate = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d camera_in_board = camera_from_board.inverse().translation();
  const double up = camera_in_board.z() > 0 ? 1.0 : -1.0;
  board_from_plate.linear() = Eigen::Vector3d(1.0, up, up).asDiagonal();
  board_from_plate.translation() = Eigen::Vector3d(0, 0, -up * thickness_mm);
  s.camera_from_plate = camera_from_board * board_from_plate;
  s.ok = true;
  s.message = "ok";
  return s;
}

std::vector<std::optional<Eigen::Vector2d>> PixelsOnPlane(
    const std::vector<Eigen::Vector2d>& pixels, const CameraIntrinsics& camera,
    const Eigen::Isometry3d& camera_from_plane) {
  const std::vector<Eigen::Vector2d> rays = camera.Undistort(pixels);
  const Eigen::Isometry3d plane_from_camera = camera_from_plane.inverse();
  const Eigen::Vector3d origin = plane_from_camera.translation();
  std::vector<std::optional<Eigen::Vector2d>> out(pixels.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    const Eigen::Vector3d dir = plane_from_camera.linear() * Eigen::Vector3d(rays[i].x(), rays[i].y(), 1.0);
    if (std::abs(dir.z()) < 1e-12) continue;
    const double t = -origin.z() / dir.z();
    if (!(t > 0)) continue;
    out[i] = (origin + t * dir).head<2>();
  }
  return out;
}

}  // namespace insitu::calib
