// Shared by the raster and vector hatchers: hatch lines are emitted boustrophedon (every other
// line reversed, its runs in reverse order) so the jump between lines is short.
#pragma once

#include <algorithm>
#include <utility>
#include <vector>

#include "insitu/pattern/raster.h"

namespace insitu::pattern {

// Appends one hatch line's runs (given in the line's direction) to `out`, reversed when
// `*forward` is false, and flips `*forward`. An empty line changes nothing.
inline void AppendHatchLine(std::vector<Segment2> line, bool* forward, std::vector<Segment2>* out) {
  if (line.empty()) return;
  if (!*forward) {
    std::reverse(line.begin(), line.end());
    for (Segment2& s : line) std::swap(s.a, s.b);
  }
  out->insert(out->end(), line.begin(), line.end());
  *forward = !*forward;
}

}  // namespace insitu::pattern
