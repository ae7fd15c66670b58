// What the room lights, taken off a frame before the stripe is sought.
//
// The stripe extractor's threshold K = k gmax and its minimum peak are gray levels above black.
// Room light on a bright part or on the walls of a step adds its own level under the stripe: the
// run above K spreads over the lit side and the centroid follows it (a column too wide, a
// centre pulled along the surface, a lit face beside the gauge taken for the line's end). With
// the line off, the camera sees only that light; the mean of a few such frames (its shot noise
// lowered by their number) is subtracted from every frame of the scan, at the scan's exposure,
// gain and region, so what remains is the stripe's own light.
#pragma once

#include <vector>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

// The mean of `frames`, rounded to the nearest gray level. Errors: invalid_argument for none,
// an empty or malformed view, or views that differ in size or bit depth.
Result<Image> AverageFrames(const std::vector<ImageView>& frames);

// frame - background per pixel, floored at 0, into *out (resized as needed). A sample at or
// above `saturation_level` (0: the frame's full scale; the stripe extractor's own level) is set
// to full scale: a clipped stripe is still refused as saturated, not measured a background's
// worth below it. Errors: invalid_argument for a malformed view or views that differ in size or
// bit depth.
Status SubtractBackground(const ImageView& frame, const ImageView& background, Image* out,
                          int saturation_level = 0);

}  // namespace insitu::vision
