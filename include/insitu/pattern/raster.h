// Raster patterns (seed 000 sec. 2.4): a grey image thresholded to a mask, placed on the part
// (scale, rotation, translation in the galvo xy plane) and filled with hatch lines at a given
// spacing and angle.
//
// Pattern coordinates: mm, origin at the image centre, x to the right, y up (image rows run
// down). A pixel is pixel_mm square.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"

namespace insitu::pattern {

struct Mask {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> on;  // row-major, 1 = mark
  bool at(int u, int v) const { return on[static_cast<size_t>(v) * width + u] != 0; }
};

// Grey image (PNG, BMP, anything OpenCV reads; colour is converted) to a mask: dark pixels
// (below `threshold`, 0..255 on the 8-bit scale) mark, or light ones with `invert`. With
// `dither`, grey levels become a density of marked pixels instead (Floyd-Steinberg error
// diffusion against `threshold`, serpentine rows): a pixel of grey g marks with probability
// ~(255 - g) / 255, so shading survives on a two-level process. Errors: not_found (no file),
// invalid_argument (not an image, empty, nothing to mark).
Result<Mask> LoadRasterMask(const std::string& path, int threshold = 128, bool invert = false,
                            bool dither = false);
// The same from the file's bytes (`path` names it in errors). Images over 64 Mpixel are
// refused (invalid_argument).
Result<Mask> DecodeRasterMask(const std::string& bytes, const std::string& path,
                              int threshold = 128, bool invert = false, bool dither = false);

struct Segment2 {
  Eigen::Vector2d a = Eigen::Vector2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
};

// Hatch lines filling the mask: lines at `angle_deg` from the pattern's x axis, `spacing_mm`
// apart (one through the pattern origin), each cut into the runs where it lies on marked
// pixels (sampled at a quarter pixel, so a run's ends are within 1/8 pixel of the pixel edge).
// Alternate lines run in opposite directions (shorter jumps). Errors: invalid_argument for a
// non-positive spacing or pixel size.
Result<std::vector<Segment2>> HatchMask(const Mask& mask, double pixel_mm, double spacing_mm,
                                        double angle_deg);

// Scale, then rotate about the pattern origin, then move: pattern mm -> galvo xy mm.
struct Placement {
  double scale = 1.0;
  double rotation_deg = 0.0;
  Eigen::Vector2d offset_mm = Eigen::Vector2d::Zero();
  Eigen::Vector2d Apply(const Eigen::Vector2d& p) const;
};

std::vector<Segment2> Place(const std::vector<Segment2>& segments, const Placement& placement);

}  // namespace insitu::pattern
