// Dimensions of a triangular cutting insert from a scan (seed 000 sec. 3.3.4, Table 1): the
// thickness, the three edge lengths with the tip-radius correction, and the hole diameter.
// The insert lies anywhere on the stage plate, at any rotation (no fixture): everything is
// found in the cloud.
//
// Method:
// - plate: median z of the points near base_z_mm; top: points higher than half the nominal
//   thickness above it;
// - per scan line, the top's runs (a gap wider than gap_mm splits a run: the hole); every run
//   end where the stripe falls to half its brightness (inspect/line_ends.h) is an edge point: the
//   first and last of a line lie on the outline, the inner ones on the hole;
// - the three edges: lines found by consensus among the outline points (within inlier_mm),
//   refitted by least squares without the points within corner_exclusion_mm of the corners
//   (the rounded tips); their intersections are the sharp corners, Li the distances between
//   them, and L = Li - 2 (sqrt(3) - 1) r with the tip radius r (the seed's correction);
// - the hole: a least-squares circle through the hole's edge points (outliers beyond
//   inlier_mm dropped once);
// - the thickness: the cutting edge's height above the plate, from a straight-line fit of the
//   top's height against the distance in from each edge over rake_fit_mm (the rake face slopes
//   down from the edge), taken at distance 0 and averaged over the three edges.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/geometry/cloud.h"

namespace insitu::inspect {

struct InsertSpec {
  // Nominal dimensions (the seed's vernier values, Table 1): edges as L (tip radius
  // corrected).
  double thickness_mm = 4.68;
  double edge_mm = 16.14;
  double hole_diameter_mm = 3.80;
  double tip_radius_mm = 0.2;
  double base_z_mm = 0.0;  // the plate the insert lies on
  // Analysis.
  double gap_mm = 0.4;                   // a gap this wide in a line's top is the hole
  double inlier_mm = 0.08;               // edge point to edge line / hole circle
  double corner_exclusion_mm = 1.0;      // tip radius + the rake's run-out at the corners
  std::array<double, 2> rake_fit_mm{0.3, 1.2};  // distances in from an edge for the thickness

  Status Validate() const;
};

struct InsertResult {
  double plate_z_mm = 0.0;
  double thickness_mm = 0.0;
  std::array<double, 3> thickness_per_edge_mm{};
  std::array<double, 3> edge_raw_mm{};  // Li: sharp corner to sharp corner
  std::array<double, 3> edge_mm{};      // L = Li - 2 (sqrt(3) - 1) r
  std::array<Eigen::Vector2d, 3> corners_mm{};
  std::array<int, 3> edge_points{};     // outline points used per edge
  double edge_fit_rms_mm = 0.0;
  Eigen::Vector2d hole_center_mm = Eigen::Vector2d::Zero();
  double hole_diameter_mm = 0.0;
  int hole_points = 0;
  double hole_fit_rms_mm = 0.0;
  // All outline and hole edge points (for the picture).
  std::vector<Eigen::Vector2d> outline_points, hole_points_mm;
};

// Errors: invalid_argument for a bad spec; not_found when no insert is in the cloud or an edge
// or the hole cannot be fitted (the message says which and with how many points).
Result<InsertResult> EvaluateInsert(const geometry::Cloud& cloud, const InsertSpec& spec);

}  // namespace insitu::inspect
