// Calibration targets in camera frames: chessboard inner corners (OpenCV's sector-based
// detector, sub-pixel) and the pointer's spot.
// Pixel coordinates as in OpenCV (pixel centres at integers).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

struct ChessboardOptions {
  int inner_cols = 11;  // inner corners along the board's x
  int inner_rows = 8;

  Status Validate() const;
};

// Corners in board order: row 0 (board y smallest) first, cols along board x. Returns
// not_found when the board is not (completely) visible.
Result<std::vector<Eigen::Vector2d>> FindChessboard(const ImageView& image,
                                                    const ChessboardOptions& options);

struct SpotOptions {
  double min_peak = 30.0;         // gray levels above the reference frame
  double threshold_ratio = 0.3;   // pixels above ratio * peak form the spot
  int max_diameter_px = 60;

  Status Validate() const;
};

struct Spot {
  Eigen::Vector2d center;  // intensity-weighted centroid, pixels
  double peak = 0.0;       // gray levels above the reference
  int pixels = 0;
};

// The pointer spot: centroid of (with - without) above threshold, around the strongest pixel.
// Both frames must have the same size and depth. not_found if there is no spot, or the
// bright region is wider than max_diameter_px (a reflection, not a spot).
Result<Spot> FindSpot(const ImageView& with_spot, const ImageView& without_spot,
                      const SpotOptions& options);

}  // namespace insitu::vision
