// Spiral-filled circle targets (seed 003 sec. 2.2) and the circle / ellipse fits.
//
// Segmentation. The plate is dark and its brightness drifts over the frame (room light,
// vignetting), so one global threshold does not fit all targets. The background is the
// morphological opening of a reduced copy of the frame with a window 1.5 times the largest
// target: every target is narrower than the window, so the opening removes it and keeps the
// plate's slow variation. What stands above the background by more than half the least
// contrast asked for (or 5 noise sigmas, the noise measured robustly on the same difference)
// is labelled; a 3 x 3 Gaussian first keeps noise pixels from fraying the blobs.
//
// Measurement, per blob. The local background is the median of a ring of plate just outside
// the blob, the plateau the median of its inner part (a median, because the spiral's start
// may have burnt the centre differently, seed 003); half way between them is the level at
// which the edge sits whatever the blur, as long as the blur is symmetric. The seed's feature
// point is the minimum enclosing circle of the outer contour of the blob cut at that level.
// The sub-pixel edge is found along rays from the blob's centroid, walking inward from the
// plate so that a bright defect inside cannot be mistaken for the edge, and interpolating the
// bilinearly sampled profile linearly at the crossing. A crossing is accepted only if the
// next pixel inward is on average above the level too (a lone noisy sample is not an edge).
// Points far off the ellipse through all of them (a scratch, a neighbour's halo) are dropped.
#include "insitu/vision/circle_targets.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include "vision/image_cv.h"

namespace insitu::vision {
namespace {

std::string Format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[200];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}



// Bilinear sample of a CV_32F image; the caller keeps (x, y) at least one pixel inside.
float Bilinear(const cv::Mat& m, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
  const float* r0 = m.ptr<float>(y0);
  const float* r1 = m.ptr<float>(y0 + 1);
  return (1 - ay) * ((1 - ax) * r0[x0] + ax * r0[x0 + 1]) +
         ay * ((1 - ax) * r1[x0] + ax * r1[x0 + 1]);
}

bool AllFinite(const std::vector<Eigen::Vector2d>& points) {
  for (const Eigen::Vector2d& p : points) {
    if (!p.allFinite()) return false;
  }
  return true;
}

// Conic A x^2 + B x y + C y^2 + D x + E y + F = 0 in coordinates (p - mean) / scale.
struct Conic {
  Eigen::Matrix<double, 6, 1> c;
  Eigen::Vector2d mean;
  double scale = 1.0;

  // First-order (Sampson) distance of p from the conic, in p's units.
  double Distance(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d q = (p - mean) / scale;
    const double x = q.x(), y = q.y();
    const double f = c[0] * x * x + c[1] * x * y + c[2] * y * y + c[3] * x + c[4] * y + c[5];
    const double gx = 2 * c[0] * x + c[1] * y + c[3];
    const double gy = c[1] * x + 2 * c[2] * y + c[4];
    const double g = std::hypot(gx, gy);
    return g > 0 ? scale * f / g : std::numeric_limits<double>::infinity();
  }
};

Result<Conic> FitConic(const std::vector<Eigen::Vector2d>& points, EllipseFit* fit) {
  if (points.size() < 5) {
    return InvalidArgument("ellipse fit needs at least 5 points, got " +
                           std::to_string(points.size()));
  }
  if (!AllFinite(points)) return InvalidArgument("ellipse fit: non-finite point");
  Conic conic;
  conic.mean.setZero();
  for (const Eigen::Vector2d& p : points) conic.mean += p;
  conic.mean /= static_cast<double>(points.size());
  double ss = 0.0;
  for (const Eigen::Vector2d& p : points) ss += (p - conic.mean).squaredNorm();
  conic.scale = std::sqrt(ss / points.size());
  if (!(conic.scale > 0)) return InvalidArgument("ellipse fit: all points coincide");

  // Halir & Flusser: split the design matrix into its quadratic and linear parts, eliminate
  // the linear part, and solve the 3 x 3 eigenproblem under the constraint 4AC - B^2 = 1.
  Eigen::Matrix3d s1 = Eigen::Matrix3d::Zero(), s2 = Eigen::Matrix3d::Zero(),
                  s3 = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector2d& p : points) {
    const Eigen::Vector2d q = (p - conic.mean) / conic.scale;
    const Eigen::Vector3d d1(q.x() * q.x(), q.x() * q.y(), q.y() * q.y());
    const Eigen::Vector3d d2(q.x(), q.y(), 1.0);
    s1 += d1 * d1.transpose();
    s2 += d1 * d2.transpose();
    s3 += d2 * d2.transpose();
  }
  Eigen::FullPivLU<Eigen::Matrix3d> lu3(s3);
  if (!lu3.isInvertible()) return InvalidArgument("ellipse fit: points are on a line");
  const Eigen::Matrix3d t = -lu3.solve(s2.transpose());
  const Eigen::Matrix3d m = s1 + s2 * t;
  Eigen::Matrix3d reduced;  // C1^-1 M, C1 = [[0 0 2] [0 -1 0] [2 0 0]]
  reduced.row(0) = m.row(2) / 2.0;
  reduced.row(1) = -m.row(1);
  reduced.row(2) = m.row(0) / 2.0;
  Eigen::EigenSolver<Eigen::Matrix3d> es(reduced);
  if (es.info() != Eigen::Success) return InvalidArgument("ellipse fit: eigen solver failed");
  int best = -1;
  double best_cond = 0.0;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d v = es.eigenvectors().col(k).real();
    const double cond = 4.0 * v[0] * v[2] - v[1] * v[1];
    if (cond > best_cond) {
      best_cond = cond;
      best = k;
    }
  }
  if (best < 0) return InvalidArgument("ellipse fit: the points determine no ellipse");
  const Eigen::Vector3d a1 = es.eigenvectors().col(best).real();
  const Eigen::Vector3d a2 = t * a1;
  conic.c << a1, a2;

  // Geometric parameters, in normalised coordinates first.
  const double A = conic.c[0], B = conic.c[1], C = conic.c[2], D = conic.c[3], E = conic.c[4];
  Eigen::Matrix2d q;
  q << A, B / 2, B / 2, C;
  const Eigen::Vector2d centre = q.ldlt().solve(Eigen::Vector2d(-D / 2, -E / 2));
  const double f_centre = 0.5 * (D * centre.x() + E * centre.y()) + conic.c[5];
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> qs(q);
  Eigen::Vector2d lambda = qs.eigenvalues();  // ascending
  double sign = 1.0;
  if (lambda[1] < 0) sign = -1.0;  // the conic's overall sign is arbitrary
  const double l_major = sign > 0 ? lambda[0] : -lambda[1];
  const double l_minor = sign > 0 ? lambda[1] : -lambda[0];
  const double fc = sign * f_centre;
  if (!(l_major > 0 && l_minor > 0 && fc < 0)) {
    return InvalidArgument("ellipse fit: the points determine no ellipse");
  }
  const Eigen::Vector2d axis = qs.eigenvectors().col(sign > 0 ? 0 : 1);
  double angle = std::atan2(axis.y(), axis.x());
  if (angle <= -M_PI / 2) angle += M_PI;
  if (angle > M_PI / 2) angle -= M_PI;
  fit->center = conic.mean + conic.scale * centre;
  fit->semi_major = conic.scale * std::sqrt(-fc / l_major);
  fit->semi_minor = conic.scale * std::sqrt(-fc / l_minor);
  fit->angle_rad = angle;
  double sum = 0.0;
  for (const Eigen::Vector2d& p : points) sum += std::pow(conic.Distance(p), 2);
  fit->rms_residual = std::sqrt(sum / points.size());
  if (!fit->center.allFinite() || !std::isfinite(fit->semi_major)) {
    return InvalidArgument("ellipse fit: degenerate points");
  }
  return conic;
}

}  // namespace

Status CircleTargetOptions::Validate() const {
  if (!(min_diameter_px > 0) || !(max_diameter_px >= min_diameter_px)) {
    return InvalidArgument(
        Format("circle targets: need 0 < min_diameter_px <= max_diameter_px, got %.6g and %.6g",
               min_diameter_px, max_diameter_px));
  }
  if (max_diameter_px > 2000) {
    return InvalidArgument(
        Format("circle targets: max_diameter_px %.6g exceeds 2000", max_diameter_px));
  }
  if (!(min_contrast_fraction > 0 && min_contrast_fraction <= 1)) {
    return InvalidArgument(
        Format("circle targets: min_contrast_fraction %.6g not in (0, 1]", min_contrast_fraction));
  }
  if (!(min_solidity >= 0 && min_solidity <= 1)) {
    return InvalidArgument(Format("circle targets: min_solidity %.6g not in [0, 1]", min_solidity));
  }
  if (!(min_axis_ratio >= 0 && min_axis_ratio <= 1)) {
    return InvalidArgument(
        Format("circle targets: min_axis_ratio %.6g not in [0, 1]", min_axis_ratio));
  }
  if (edge_rays < 0 || edge_rays > 4096) {
    return InvalidArgument("circle targets: edge_rays " + std::to_string(edge_rays) +
                           " not in [0, 4096]");
  }
  return Status::Ok();
}

Result<std::vector<CircleTarget>> FindCircleTargets(const ImageView& image,
                                                    const CircleTargetOptions& o,
                                                    std::vector<RejectedBlob>* rejected) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  INSITU_RETURN_IF_ERROR(CheckImageView(image, ""));
  if (rejected != nullptr) rejected->clear();
  std::vector<CircleTarget> targets;
  try {
    const cv::Mat raw = ToFloatMat(image);
    cv::Mat smooth;
    cv::GaussianBlur(raw, smooth, cv::Size(3, 3), 0.8, 0.8, cv::BORDER_REPLICATE);

    // Background: opening of a reduced copy (fast at 5 MP: the window is ~12 px there).
    const int reduce = std::max(1, static_cast<int>(o.max_diameter_px / 10.0));
    cv::Mat small;
    cv::resize(smooth, small,
               cv::Size(std::max(1, image.width / reduce), std::max(1, image.height / reduce)), 0,
               0, cv::INTER_AREA);
    const int k = 2 * static_cast<int>(std::ceil(0.75 * o.max_diameter_px / reduce)) + 1;
    cv::Mat opened;
    cv::morphologyEx(small, opened, cv::MORPH_OPEN,
                     cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)), cv::Point(-1, -1),
                     1, cv::BORDER_REPLICATE);
    cv::blur(opened, opened, cv::Size(k, k), cv::Point(-1, -1), cv::BORDER_REPLICATE);
    cv::Mat background;
    cv::resize(opened, background, raw.size(), 0, 0, cv::INTER_LINEAR);
    const cv::Mat lift = smooth - background;

    // Noise of the difference, robustly (median and MAD of a sparse sample).
    double lift_median, sigma;
    RobustLevel(lift, 4, &lift_median, &sigma);
    const double min_contrast = o.min_contrast_fraction * image.max_value();
    const double cut = lift_median + std::max(0.5 * min_contrast, 5.0 * sigma);
    cv::Mat mask = lift > cut;

    cv::Mat labels, stats, centroids;
    const int n = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
    const double min_area = M_PI / 4 * std::pow(0.5 * o.min_diameter_px, 2);
    const auto reject = [&](const Eigen::Vector2d& c, double d, std::string why) {
      if (rejected != nullptr) rejected->push_back({c, d, std::move(why)});
    };
    for (int l = 1; l < n; ++l) {
      const int area = stats.at<int>(l, cv::CC_STAT_AREA);
      if (area < min_area) continue;  // noise
      const double d_eq = std::sqrt(4.0 * area / M_PI);
      const Eigen::Vector2d c0(centroids.at<double>(l, 0), centroids.at<double>(l, 1));
      const int bx = stats.at<int>(l, cv::CC_STAT_LEFT), by = stats.at<int>(l, cv::CC_STAT_TOP);
      const int bw = stats.at<int>(l, cv::CC_STAT_WIDTH), bh = stats.at<int>(l, cv::CC_STAT_HEIGHT);
      if (bx == 0 || by == 0 || bx + bw == image.width || by + bh == image.height) {
        reject(c0, d_eq, "cut off by the image border");
        continue;
      }
      if (d_eq < o.min_diameter_px) {
        reject(c0, d_eq,
               Format("too small: %.1f px across, min_diameter_px %.1f", d_eq, o.min_diameter_px));
        continue;
      }
      if (d_eq > o.max_diameter_px) {
        reject(c0, d_eq,
               Format("too large: %.1f px across, max_diameter_px %.1f", d_eq, o.max_diameter_px));
        continue;
      }
      const int margin = static_cast<int>(std::ceil(0.75 * std::max(bw, bh))) + 4;
      const cv::Rect roi = cv::Rect(bx - margin, by - margin, bw + 2 * margin, bh + 2 * margin) &
                           cv::Rect(0, 0, image.width, image.height);
      const cv::Mat roi_raw = raw(roi), roi_smooth = smooth(roi), roi_labels = labels(roi);
      const cv::Mat own = roi_labels == l;

      // Local levels: a ring of plate outside the blob, the blob's inner part.
      const double r0 = 0.5 * std::max(bw, bh);
      const double ring_in = r0 + 3.0, ring_out = ring_in + std::max(4.0, 0.5 * r0);
      std::vector<float> ring, inner;
      for (int v = 0; v < roi.height; ++v) {
        const int* lab = roi_labels.ptr<int>(v);
        const float* val = roi_raw.ptr<float>(v);
        for (int u = 0; u < roi.width; ++u) {
          const double d = std::hypot(roi.x + u - c0.x(), roi.y + v - c0.y());
          if (lab[u] == 0 && d >= ring_in && d <= ring_out) ring.push_back(val[u]);
        }
      }
      cv::Mat core;
      cv::erode(own, core, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
      if (cv::countNonZero(core) == 0) core = own;
      for (int v = 0; v < roi.height; ++v) {
        const uint8_t* in = core.ptr<uint8_t>(v);
        const float* val = roi_raw.ptr<float>(v);
        for (int u = 0; u < roi.width; ++u) {
          if (in[u]) inner.push_back(val[u]);
        }
      }
      if (ring.size() < 12) {
        reject(c0, d_eq, "too little plate around it to measure the background");
        continue;
      }
      const double bg = MedianInPlace(ring), plateau = MedianInPlace(inner);
      if (plateau - bg < min_contrast) {
        reject(c0, d_eq,
               Format("contrast %.1f gray levels below the least asked for, %.1f", plateau - bg,
                      min_contrast));
        continue;
      }
      const double half = 0.5 * (bg + plateau);

      // Seed 003: the outer contour of the blob cut at the half level (other blobs masked).
      cv::Mat cut_mask = (roi_smooth > half) & ((roi_labels == 0) | own);
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(cut_mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
      int chosen = -1;
      double chosen_area = -1.0;
      const cv::Point2f c0_roi(static_cast<float>(c0.x() - roi.x),
                               static_cast<float>(c0.y() - roi.y));
      for (size_t i = 0; i < contours.size(); ++i) {
        const double a = cv::contourArea(contours[i]);
        const bool holds = cv::pointPolygonTest(contours[i], c0_roi, false) >= 0;
        if (holds && a > chosen_area) {
          chosen = static_cast<int>(i);
          chosen_area = a;
        }
      }
      if (chosen < 0 || contours[chosen].size() < 5) {
        reject(c0, d_eq, "no closed outline at the half-way level around its centre");
        continue;
      }
      const std::vector<cv::Point>& contour = contours[chosen];
      std::vector<cv::Point> hull;
      cv::convexHull(contour, hull);
      const double hull_area = cv::contourArea(hull);
      const double solidity = hull_area > 0 ? chosen_area / hull_area : 0.0;
      if (solidity < o.min_solidity) {
        reject(c0, d_eq,
               Format("not a solid disc: solidity %.2f below %.2f", solidity, o.min_solidity));
        continue;
      }
      cv::Mat filled = cv::Mat::zeros(roi.size(), CV_8U);
      cv::drawContours(filled, contours, chosen, cv::Scalar(255), cv::FILLED);
      const cv::Moments mo = cv::moments(filled, true);
      const double mu20 = mo.mu20 / mo.m00, mu02 = mo.mu02 / mo.m00, mu11 = mo.mu11 / mo.m00;
      const double mid = 0.5 * (mu20 + mu02);
      const double spread = std::sqrt(0.25 * (mu20 - mu02) * (mu20 - mu02) + mu11 * mu11);
      const double axis_ratio = mid + spread > 0 ? std::sqrt((mid - spread) / (mid + spread)) : 0;
      if (axis_ratio < o.min_axis_ratio) {
        reject(c0, d_eq,
               Format("elongated: axis ratio %.2f below %.2f", axis_ratio, o.min_axis_ratio));
        continue;
      }
      CircleTarget t;
      cv::Point2f mec_centre;
      float mec_radius = 0.0f;
      cv::minEnclosingCircle(contour, mec_centre, mec_radius);
      t.mec_center_px = Eigen::Vector2d(mec_centre.x + roi.x, mec_centre.y + roi.y);
      t.mec_radius_px = mec_radius;
      t.area_px = mo.m00;
      t.centroid_px = Eigen::Vector2d(mo.m10 / mo.m00 + roi.x, mo.m01 / mo.m00 + roi.y);
      t.background = bg;
      t.plateau = plateau;

      // Sub-pixel edge along rays, walking in from the plate.
      const int rays = o.edge_rays > 0
                           ? o.edge_rays
                           : std::max(32, static_cast<int>(std::ceil(2 * M_PI * mec_radius)));
      t.edge_rays = rays;
      constexpr double kStep = 0.25;
      const double r_start = 1.5 * mec_radius + 2.0, r_stop = 0.3 * mec_radius;
      const int samples = static_cast<int>((r_start - r_stop) / kStep) + 1;
      std::vector<float> profile(samples);
      std::vector<char> usable(samples);
      const Eigen::Vector2d c = t.centroid_px;
      for (int ray = 0; ray < rays; ++ray) {
        const double angle = 2.0 * M_PI * ray / rays;
        const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
        for (int s = 0; s < samples; ++s) {
          const Eigen::Vector2d p = c + (r_start - s * kStep) * dir;
          const int pu = static_cast<int>(std::floor(p.x())),
                    pv = static_cast<int>(std::floor(p.y()));
          const int nu = static_cast<int>(std::lround(p.x())),
                    nv = static_cast<int>(std::lround(p.y()));
          usable[s] = pu >= 0 && pv >= 0 && pu + 1 < image.width && pv + 1 < image.height;
          if (usable[s]) {
            const int lab = labels.at<int>(nv, nu);
            usable[s] = lab == 0 || lab == l;
          }
          profile[s] = usable[s] ? Bilinear(raw, p.x(), p.y()) : 0.0f;
        }
        const int confirm = static_cast<int>(std::lround(1.0 / kStep));
        for (int s = 1; s + confirm < samples; ++s) {
          if (!usable[s - 1] || !usable[s] || profile[s - 1] >= half || profile[s] < half) {
            continue;
          }
          double ahead = 0.0;
          bool ok = true;
          for (int j = 1; j <= confirm; ++j) {
            ok = ok && usable[s + j];
            ahead += profile[s + j];
          }
          if (!ok || ahead / confirm < half) continue;
          const double frac = (half - profile[s - 1]) / (profile[s] - profile[s - 1]);
          const double r = r_start - (s - 1 + frac) * kStep;
          t.edge_px.push_back(c + r * dir);
          break;
        }
      }
      const int found = static_cast<int>(t.edge_px.size());
      if (found < std::max(5, rays / 2)) {
        reject(c0, d_eq,
               "edge found on only " + std::to_string(found) + " of " + std::to_string(rays) +
                   " rays");
        continue;
      }
      EllipseFit ellipse;
      auto conic = FitConic(t.edge_px, &ellipse);
      if (!conic.ok()) {
        reject(c0, d_eq, "edge is not an ellipse: " + conic.status().message());
        continue;
      }
      std::vector<float> dist;
      for (const Eigen::Vector2d& p : t.edge_px) {
        dist.push_back(static_cast<float>(std::abs(conic->Distance(p))));
      }
      const double limit = std::max(0.3, 4.0 * kMadToSigma * Median(dist));
      std::vector<Eigen::Vector2d> kept;
      for (size_t i = 0; i < dist.size(); ++i) {
        if (dist[i] <= limit) kept.push_back(t.edge_px[i]);
      }
      t.edge_px = std::move(kept);
      if (static_cast<int>(t.edge_px.size()) < std::max(5, rays / 2)) {
        reject(c0, d_eq,
               "edge too ragged: " + std::to_string(t.edge_px.size()) + " of " +
                   std::to_string(rays) + " rays near one ellipse");
        continue;
      }
      targets.push_back(std::move(t));
    }
  } catch (const cv::Exception& e) {
    return Internal(std::string("circle target detection failed: ") + e.what());
  }
  return targets;
}

Result<CircleFit> FitCircle(const std::vector<Eigen::Vector2d>& points) {
  if (points.size() < 3) {
    return InvalidArgument("circle fit needs at least 3 points, got " +
                           std::to_string(points.size()));
  }
  if (!AllFinite(points)) return InvalidArgument("circle fit: non-finite point");
  // Taubin's fit (Chernov's Newton form) on centred points scaled to unit rms radius.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double ss = 0.0;
  for (const Eigen::Vector2d& p : points) ss += (p - mean).squaredNorm();
  const double scale = std::sqrt(ss / points.size());
  if (!(scale > 0)) return InvalidArgument("circle fit: all points coincide");
  double mxx = 0, myy = 0, mxy = 0, mxz = 0, myz = 0, mzz = 0;
  for (const Eigen::Vector2d& p : points) {
    const double x = (p.x() - mean.x()) / scale, y = (p.y() - mean.y()) / scale;
    const double z = x * x + y * y;
    mxx += x * x;
    myy += y * y;
    mxy += x * y;
    mxz += x * z;
    myz += y * z;
    mzz += z * z;
  }
  const double count = static_cast<double>(points.size());
  mxx /= count, myy /= count, mxy /= count, mxz /= count, myz /= count, mzz /= count;
  const double mz = mxx + myy;
  const double cov_xy = mxx * myy - mxy * mxy;
  const double var_z = mzz - mz * mz;
  // The smallest eigenvalue of the points' scatter: zero when they lie on a line.
  if (cov_xy < 1e-12 * mz * mz) return InvalidArgument("circle fit: points are on a line");
  const double a3 = 4 * mz, a2 = -3 * mz * mz - mzz;
  const double a1 = var_z * mz + 4 * cov_xy * mz - mxz * mxz - myz * myz;
  const double a0 = mxz * (mxz * myy - myz * mxy) + myz * (myz * mxx - mxz * mxy) - var_z * cov_xy;
  double x = 0.0, y = a0;
  for (int i = 0; i < 99; ++i) {
    const double dy = a1 + x * (2 * a2 + 3 * a3 * x);
    const double x_new = x - y / dy;
    if (x_new == x || !std::isfinite(x_new)) break;
    const double y_new = a0 + x_new * (a1 + x_new * (a2 + x_new * a3));
    if (std::abs(y_new) >= std::abs(y)) break;
    x = x_new;
    y = y_new;
  }
  const double det = x * x - x * mz + cov_xy;
  if (!(std::abs(det) > 1e-15)) return InvalidArgument("circle fit: points are on a line");
  const Eigen::Vector2d cn((mxz * (myy - x) - myz * mxy) / det / 2,
                           (myz * (mxx - x) - mxz * mxy) / det / 2);
  Eigen::Vector3d q(cn.x(), cn.y(), std::sqrt(cn.squaredNorm() + mz));  // centre, radius
  if (!q.allFinite()) return InvalidArgument("circle fit: points are on a line");

  // Gauss-Newton on the geometric residuals |p - c| - r (normalised coordinates).
  const auto cost = [&](const Eigen::Vector3d& s) {
    double sum = 0.0;
    for (const Eigen::Vector2d& p : points) {
      const Eigen::Vector2d d = (p - mean) / scale - s.head<2>();
      sum += std::pow(d.norm() - s[2], 2);
    }
    return sum;
  };
  CircleFit fit;
  double current = cost(q);
  for (int it = 0; it < 50; ++it) {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jte = Eigen::Vector3d::Zero();
    for (const Eigen::Vector2d& p : points) {
      const Eigen::Vector2d d = (p - mean) / scale - q.head<2>();
      const double len = d.norm();
      const Eigen::Vector3d j =
          len > 0 ? Eigen::Vector3d(-d.x() / len, -d.y() / len, -1.0) : Eigen::Vector3d(0, 0, -1);
      jtj += j * j.transpose();
      jte += j * (len - q[2]);
    }
    Eigen::Vector3d step = jtj.ldlt().solve(-jte);
    if (!step.allFinite()) break;
    // Halve a step that would raise the cost (far from the minimum only).
    double next = cost(q + step);
    for (int h = 0; h < 20 && next > current; ++h) {
      step *= 0.5;
      next = cost(q + step);
    }
    if (next > current) break;
    q += step;
    current = next;
    fit.iterations = it + 1;
    if (step.norm() < 1e-12 * q[2]) break;
  }
  fit.center = mean + scale * q.head<2>();
  fit.radius = scale * q[2];
  fit.rms_residual = scale * std::sqrt(current / count);
  return fit;
}

Result<EllipseFit> FitEllipse(const std::vector<Eigen::Vector2d>& points) {
  EllipseFit fit;
  auto conic = FitConic(points, &fit);
  if (!conic.ok()) return conic.status();
  return fit;
}

}  // namespace insitu::vision
