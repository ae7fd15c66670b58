#include "insitu/pattern/raster.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string_view>
#include <utility>

#include "pattern/hatch_order.h"

namespace insitu::pattern {
namespace {

// A pattern image: 64 Mpixel (8192 x 8192) and a 256 MB file are far beyond any mark (at
// 0.01 mm per pixel, 82 mm square) and keep a decoded mask and its dither buffer (4 bytes a
// pixel) within ~400 MB.
constexpr int64_t kMaxImagePixels = 64ll << 20;
constexpr uintmax_t kMaxImageFileBytes = 256ull << 20;

}  // namespace

Result<Mask> LoadRasterMask(const std::string& path, int threshold, bool invert, bool dither) {
  if (!std::filesystem::exists(path)) return NotFound(path + ": no such pattern image");
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return NotFound(path + ": cannot read the pattern image (" + ec.message() + ")");
  if (size > kMaxImageFileBytes) {
    return InvalidArgument(path + ": " + std::to_string(size) +
                           " bytes is larger than a pattern image may be (256 MB)");
  }
  std::ifstream f(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (!f.good() && !f.eof()) return NotFound(path + ": cannot read the pattern image");
  return DecodeRasterMask(bytes, path, threshold, invert, dither);
}

Result<Mask> DecodeRasterMask(const std::string& bytes, const std::string& path, int threshold,
                              bool invert, bool dither) {
  if (threshold < 0 || threshold > 255) {
    return InvalidArgument("threshold must be in 0..255, got " + std::to_string(threshold));
  }
  // Only the formats a pattern comes in reach OpenCV's decoders: it registers many more
  // (DICOM through GDCM, OpenEXR, Radiance HDR, JPEG 2000, ...), and GDCM aborts the process
  // on a malformed file (found by tests/fuzz/image_fuzz.cc).
  const auto starts = [&](std::string_view magic) {
    return bytes.size() >= magic.size() && std::string_view(bytes).substr(0, magic.size()) == magic;
  };
  const bool known = starts("\x89PNG\r\n\x1a\n") || starts("\xff\xd8\xff") || starts("BM") ||
                     starts(std::string_view("II*\0", 4)) ||
                     starts(std::string_view("MM\0*", 4)) ||
                     // PNM: "P1".."P6" then whitespace, as OpenCV's PNM decoder checks (else
                     // OpenCV would try its other decoders on it).
                     (bytes.size() >= 3 && bytes[0] == 'P' && bytes[1] >= '1' && bytes[1] <= '6' &&
                      std::isspace(static_cast<unsigned char>(bytes[2])));
  if (!known) {
    return InvalidArgument(path + ": not a PNG, JPEG, BMP, TIFF or PNM (PBM/PGM/PPM) image");
  }
  cv::Mat img;
  try {
    // OpenCV itself refuses images over 2^30 pixels while decoding (CV_IO_MAX_IMAGE_PIXELS);
    // a pattern's own limit is checked after.
    const cv::Mat raw(1, static_cast<int>(bytes.size()), CV_8U,
                      const_cast<char*>(bytes.data()));
    if (bytes.empty()) return InvalidArgument(path + ": empty image file");
    img = cv::imdecode(raw, cv::IMREAD_GRAYSCALE | cv::IMREAD_ANYDEPTH);
  } catch (const cv::Exception& e) {
    return InvalidArgument(path + ": not an image OpenCV can read (" + e.err + ")");
  }
  if (img.empty()) return InvalidArgument(path + ": not an image OpenCV can read");
  if (static_cast<int64_t>(img.cols) * img.rows > kMaxImagePixels) {
    return InvalidArgument(path + ": " + std::to_string(img.cols) + " x " +
                           std::to_string(img.rows) +
                           " pixels is more than a pattern image may have (64 Mpixel)");
  }
  if (img.depth() != CV_8U) img.convertTo(img, CV_8U, img.depth() == CV_16U ? 1.0 / 257.0 : 1.0);
  Mask m;
  m.width = img.cols;
  m.height = img.rows;
  m.on.resize(static_cast<size_t>(m.width) * m.height);
  size_t count = 0;
  if (dither) {
    // Ink (0 = none, 255 = full) diffused Floyd-Steinberg: 7/16 ahead, 3/16,
    // 5/16, 1/16 below; rows alternate direction so the error does not stream
    // to one side.
    cv::Mat ink;
    img.convertTo(ink, CV_32F);
    if (!invert) ink = 255.0f - ink;
    for (int v = 0; v < m.height; ++v) {
      const bool ltr = v % 2 == 0;
      float* row = ink.ptr<float>(v);
      float* below = v + 1 < m.height ? ink.ptr<float>(v + 1) : nullptr;
      for (int k = 0; k < m.width; ++k) {
        const int u = ltr ? k : m.width - 1 - k, ahead = ltr ? u + 1 : u - 1,
                  back = ltr ? u - 1 : u + 1;
        const bool mark = row[u] >= 255.0f - static_cast<float>(threshold);
        const float err = row[u] - (mark ? 255.0f : 0.0f);
        m.on[static_cast<size_t>(v) * m.width + u] = mark;
        count += mark;
        if (ahead >= 0 && ahead < m.width) row[ahead] += err * 7.0f / 16.0f;
        if (below) {
          if (back >= 0 && back < m.width) below[back] += err * 3.0f / 16.0f;
          below[u] += err * 5.0f / 16.0f;
          if (ahead >= 0 && ahead < m.width) below[ahead] += err * 1.0f / 16.0f;
        }
      }
    }
  } else {
    for (int v = 0; v < m.height; ++v) {
      const uint8_t* row = img.ptr<uint8_t>(v);
      for (int u = 0; u < m.width; ++u) {
        const bool dark = row[u] < threshold;
        const bool mark = invert ? !dark : dark;
        m.on[static_cast<size_t>(v) * m.width + u] = mark;
        count += mark;
      }
    }
  }
  if (count == 0)
    return InvalidArgument(path + ": no pixel to mark at threshold " + std::to_string(threshold));
  return m;
}

Result<std::vector<Segment2>> HatchMask(const Mask& mask, double pixel_mm, double spacing_mm,
                                        double angle_deg) {
  if (!(pixel_mm > 0)) return InvalidArgument("pixel_mm must be > 0");
  if (!(spacing_mm > 0)) return InvalidArgument("hatch spacing must be > 0");
  if (mask.width <= 0 || mask.height <= 0) return InvalidArgument("the mask is empty");
  const double a = angle_deg * M_PI / 180.0;
  const Eigen::Vector2d dir(std::cos(a), std::sin(a)), across(-std::sin(a), std::cos(a));
  const double half_w = 0.5 * mask.width * pixel_mm, half_h = 0.5 * mask.height * pixel_mm;
  // Lines cover the mask's bounding circle.
  const double reach = std::hypot(half_w, half_h);
  const double step = 0.25 * pixel_mm;
  auto marked = [&](const Eigen::Vector2d& p) {
    const int u = static_cast<int>(std::floor((p.x() + half_w) / pixel_mm));
    const int v = static_cast<int>(std::floor((half_h - p.y()) / pixel_mm));
    return u >= 0 && v >= 0 && u < mask.width && v < mask.height && mask.at(u, v);
  };
  std::vector<Segment2> out;
  const int k_max = static_cast<int>(std::floor(reach / spacing_mm));
  bool forward = true;
  for (int k = -k_max; k <= k_max; ++k) {
    const Eigen::Vector2d base = k * spacing_mm * across;
    std::vector<Segment2> line;
    const int n = static_cast<int>(std::ceil(2 * reach / step));
    int start = -1;
    for (int i = 0; i <= n + 1; ++i) {
      const bool on = i <= n && marked(base + (-reach + i * step) * dir);
      if (on && start < 0) start = i;
      if (!on && start >= 0) {
        // The run covers samples start..i-1; its ends lie half a sample beyond
        // them.
        const double t0 = -reach + (start - 0.5) * step, t1 = -reach + (i - 0.5) * step;
        line.push_back({base + t0 * dir, base + t1 * dir});
        start = -1;
      }
    }
    AppendHatchLine(std::move(line), &forward, &out);
  }
  return out;
}

Eigen::Vector2d Placement::Apply(const Eigen::Vector2d& p) const {
  const double a = rotation_deg * M_PI / 180.0;
  const Eigen::Vector2d s = scale * p;
  return Eigen::Vector2d(std::cos(a) * s.x() - std::sin(a) * s.y(),
                         std::sin(a) * s.x() + std::cos(a) * s.y()) +
         offset_mm;
}

std::vector<Segment2> Place(const std::vector<Segment2>& segments, const Placement& placement) {
  std::vector<Segment2> out;
  out.reserve(segments.size());
  for (const Segment2& s : segments) out.push_back({placement.Apply(s.a), placement.Apply(s.b)});
  return out;
}

}  // namespace insitu::pattern
