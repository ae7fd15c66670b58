// Spiral-filled circle targets (seed 003 sec. 2.2, Fig. 8c and 9) in a camera frame, and the
// circle and ellipse fits a caller needs to turn them into centres on the plate.
//
// The targets are light discs on a darker plate (on black anodised aluminium the laser bares
// the metal), some tens of pixels across; seen from the side camera they are ellipses. Pixel
// coordinates as in OpenCV: the centre of pixel (u, v) is at (u, v).
//
// For every target FindCircleTargets reports three things:
//  * seed 003's feature point: the centre of cv::minEnclosingCircle of the blob's outer
//    contour, with its radius. The outer contour ignores whatever the spiral's start burnt at
//    the centre, which is why the seed chose it; but it rests on the two or three outermost
//    contour pixels, so it moves by a fair fraction of a pixel with noise and with the disc's
//    position against the pixel grid;
//  * the area centroid of the (hole-filled) blob;
//  * the sub-pixel outer edge: points where the gray level, walking inward along rays from the
//    centroid, crosses half way between the target's local background and its plateau.
//
// None of these pixel positions is the image of the disc's centre. The image of a circle under
// perspective is an ellipse, and the ellipse's centre is the image of the pole (with respect to
// the circle) of the line where the plate meets the plane through the camera's centre parallel
// to the sensor; on the plate that point lies R^2 sin(beta) / Z from the circle's centre,
// toward the camera (beta: angle between the optical axis and the plate's normal; Z: the
// target's depth along the axis). For a 2.5 mm disc seen from 350 mm at 31 deg that is 2.3 um,
// as large as the accuracy a field calibration wants; lens distortion bends the ellipse too.
// The perspective-correct centre comes from mapping the edge points onto the plate plane
// (undistort, intersect the pixel rays with the plane) and fitting a circle there with
// FitCircle: the caller does that, since it holds the calibration.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

struct CircleTargetOptions {
  // Accepted size of a target: the diameter of a disc with the blob's area, pixels.
  double min_diameter_px = 8.0;
  double max_diameter_px = 80.0;
  // Least plateau - background difference, as a fraction of the image's full scale
  // (ImageView::max_value()), so one setting serves 8- and 12-bit frames.
  double min_contrast_fraction = 0.03;
  // Blob area over the area of its convex hull (a disc ~0.95; two touching discs, a scratch
  // or a crescent less).
  double min_solidity = 0.85;
  // Minor over major axis of the blob's second moments (a disc seen at 31 deg from its
  // normal: cos 31 deg = 0.86; a line much less).
  double min_axis_ratio = 0.5;
  // Rays for the sub-pixel edge; 0: about one per pixel of the perimeter (at least 32).
  int edge_rays = 0;

  // invalid_argument naming the field: sizes not positive or min > max, a fraction outside
  // (0, 1], edge_rays negative or more than 4096.
  Status Validate() const;
};

struct CircleTarget {
  // Seed 003: centre and radius of the minimum enclosing circle of the outer contour (the
  // contour runs through the centres of the blob's boundary pixels).
  Eigen::Vector2d mec_center_px = Eigen::Vector2d::Zero();
  double mec_radius_px = 0.0;
  // Centroid and area of the blob (holes filled), segmented at the half-way level.
  Eigen::Vector2d centroid_px = Eigen::Vector2d::Zero();
  double area_px = 0.0;
  // Local levels the edge is measured against, gray levels of the image: the median of a ring
  // of plate around the target and the median of the target's inner part.
  double background = 0.0;
  double plateau = 0.0;
  // Sub-pixel outer edge points, one per ray that found the edge, in order of the ray's angle
  // atan2(v - v_c, u - u_c) from 0 (rays evenly spaced in angle about the centroid). Points
  // more than 4 robust sigmas (and 0.3 px) off the ellipse fitted to all of them have been
  // dropped.
  std::vector<Eigen::Vector2d> edge_px;
  int edge_rays = 0;  // rays cast (edge_px.size() of them found the edge)
};

// A light blob that was not accepted as a target, and why, so a job can say "target near
// pixel (u, v) rejected: ...". Blobs smaller than half of min_diameter_px are noise and are
// not listed.
struct RejectedBlob {
  Eigen::Vector2d center_px = Eigen::Vector2d::Zero();  // centroid of its pixels
  double diameter_px = 0.0;                             // equivalent diameter
  std::string reason;                                   // one line, with the numbers
};

// Finds every light disc-shaped target in the frame (8-bit, or 16-bit holding bit_depth bits).
// The plate's background is estimated locally (a morphological opening of a reduced copy,
// wider than the largest target), so uneven room light and vignetting do not matter; blobs
// above it are thresholded at max(min contrast / 2, 5 noise sigmas), labelled (8-connected) and
// checked in turn: inside the frame, size, contrast, solidity, axis ratio, edge found on at
// least half the rays. Targets come back in the order of their topmost pixel (raster order),
// not in grid order: sorting into the n x n layout is the caller's, which knows it (seed 003
// step 6). `rejected`, if given, receives the blobs turned down.
// Errors: invalid_argument for an empty image, a bit depth other than 8 or 10..16, a stride
// shorter than a row, or invalid options; internal if OpenCV throws. No targets is not an
// error (an empty vector).
Result<std::vector<CircleTarget>> FindCircleTargets(const ImageView& image,
                                                    const CircleTargetOptions& options,
                                                    std::vector<RejectedBlob>* rejected = nullptr);

struct CircleFit {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius = 0.0;
  double rms_residual = 0.0;  // rms of |p - center| - radius, in the points' units
  int iterations = 0;         // Gauss-Newton iterations taken
};

// Least-squares circle through points in any planar frame (pixels, or mm on the plate after
// mapping the edge): Taubin's algebraic fit (nearly unbiased, no iteration needed to start),
// then Gauss-Newton on the geometric distances |p - c| - r until the step is below 1e-12 of
// the radius (at most 50 iterations). Errors: invalid_argument for fewer than 3 points,
// non-finite coordinates, or points on a line.
Result<CircleFit> FitCircle(const std::vector<Eigen::Vector2d>& points);

struct EllipseFit {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double semi_major = 0.0;
  double semi_minor = 0.0;
  double angle_rad = 0.0;     // of the major axis from the first coordinate axis, (-pi/2, pi/2]
  double rms_residual = 0.0;  // rms Sampson distance (first-order geometric distance)
};

// Direct least-squares ellipse (Fitzgibbon, Pilu and Fisher 1999, in the numerically stable
// form of Halir and Flusser 1998) on centred and scaled points: always an ellipse, one linear
// solve, no iteration. Errors: invalid_argument for fewer than 5 points, non-finite
// coordinates, or points that determine no ellipse (on a line, or on a hyperbola).
Result<EllipseFit> FitEllipse(const std::vector<Eigen::Vector2d>& points);

}  // namespace insitu::vision
