// Groove centres against the design's contours (seed 002, section 2.2): the measured centres and
// the design's points are split into contours by Euclidean clustering (PCL, Fig. 5), measured
// contours are matched to design contours by their nearest centroids (eq. 20), and each matched
// pair's error is split as Fig. 6 does:
//   offset  E = centroid(design) - centroid(measured) (eq. 21): the datum between the machine
//           and the part, the machine's static error;
//   scale   about the design contour's centroid, after the offset, fitted to the displacements
//           across the line: the panel's elastic bending once clamped (grows with the distance
//           from the centroid);
//   local   what is left at each design point against its matched measured point (eq. 22's
//           bidirectional nearest-point matching with its three cases): the machine's dynamics.
// Each design point's error is e_i = |E| + |P_i - Q'_j| (eq. 23, both factors 1).
// Points are in the workpiece frame, mm (x, y; the panel's surface coordinates).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::inspect {

using Points2 = std::vector<Eigen::Vector2d>;

// Clusters of points no farther than `tolerance_mm` from a neighbour in the cluster (seed 002:
// 5 mm for contours whose points are dense along them and far apart across them); clusters
// smaller than `min_points` are dropped. Each cluster: indices into `points`, in input order.
std::vector<std::vector<int>> ClusterPoints(const Points2& points, double tolerance_mm,
                                            int min_points = 3);

struct ContourMatch {
  int design = -1, measured = -1;  // indices into the given contour lists
  double centroid_distance_mm = 0.0;
};
// Each measured contour to the design contour of the nearest centroid (eq. 20), one to one:
// pairs are taken closest first, so two measured contours never share a design contour. A
// measured contour whose nearest free design centroid is farther than `max_distance_mm` is
// left unmatched.
std::vector<ContourMatch> MatchContours(const std::vector<Points2>& design,
                                        const std::vector<Points2>& measured,
                                        double max_distance_mm);

struct ContourError {
  // The design points the errors are given at: the design polyline (its points in order,
  // closed when its ends meet) resampled at the measured points' spacing, since eq. 22's
  // correction assumes both sets equally dense.
  Points2 design;
  Eigen::Vector2d offset_mm = Eigen::Vector2d::Zero();  // E, eq. 21
  // The bending (a clamped panel's, seed 002's "bending deformation error"): measured (after the
  // offset) against design about its centroid, as an isotropic scale and a stretch (a
  // symmetric, trace-free strain: one axis longer, the one across it shorter; its magnitude).
  double scale_pct = 0.0;
  double stretch_pct = 0.0;
  // What the measured points determined: "offset, scale, stretch", or less for a part of a
  // contour (the rest reported 0, left in the local error).
  std::string fitted;
  std::vector<int> matched;      // per design point: the measured point matched (eq. 22)
  std::vector<double> local_mm;  // per design point: |P_i - Q'_j|
  // With the scale taken out too: the matched point's distance to the scaled design line
  // (nearest-point matching sees only what moved across the line).
  std::vector<double> local_after_scale_mm;
  std::vector<double> error_mm;  // per design point: e_i = |E| + |P_i - Q'_j| (eq. 23)
  double local_rms_mm = 0.0, local_max_mm = 0.0;  // after offset and scale
};
// Errors: invalid_argument for an empty contour or a point that is not a number.
// `closed`: the design's last point joins its first (a CAD contour's closed flag). Without it,
// a design whose ends are as close as its points are is taken as closed.
Result<ContourError> CompareContour(const Points2& design, const Points2& measured,
                                    bool closed = false);

}  // namespace insitu::inspect
