// Shared by the vector readers (HPGL, SVG, DXF): reading a pattern file, and how many chords
// flatten a circular arc within a tolerance.
#pragma once

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "insitu/core/status.h"

namespace insitu::pattern {

// The whole file as text. Errors: not_found naming the file and what it was meant to be
// ("plot", "SVG", "DXF").
inline Result<std::string> ReadPatternFile(const std::string& path, const std::string& what) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return NotFound(path + ": cannot open the " + what + " file");
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Chords for an arc of radius `r` (mm) sweeping `angle` (rad) so that none departs from the
// arc by more than `tol` (mm): the sagitta r (1 - cos(a / 2)) of a chord of angle a; at least
// `min_chords`.
inline int ArcChords(double r, double angle, double tol, int min_chords) {
  const double step = 2.0 * std::acos(std::max(-1.0, 1.0 - tol / std::max(r, 1e-9)));
  return std::max(min_chords, static_cast<int>(std::ceil(std::abs(angle) / std::max(step, 1e-3))));
}

}  // namespace insitu::pattern
