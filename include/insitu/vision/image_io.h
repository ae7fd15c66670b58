// Writing a camera image to a file, through OpenCV's codecs (which stay in vision/).
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

// Writes `image` as a gray PNG at `path` (8-bit, or 16-bit for deeper samples). Errors:
// invalid_argument for an empty or malformed view, device_error naming the file (cannot encode
// or write it).
Status WritePng(const std::string& path, const ImageView& image);

}  // namespace insitu::vision
