#include "insitu/job/pattern_inspect.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "insitu/vision/canvas.h"

namespace insitu::job {

Status PatternInspectOptions::Validate() const {
  if (!(scale > 0 && std::isfinite(scale))) return InvalidArgument("scale must be > 0");
  if (!(hatch_spacing_mm > 0 && std::isfinite(hatch_spacing_mm))) {
    return InvalidArgument("hatch spacing must be > 0 mm");
  }
  for (double a : hatch_angles_deg) {
    if (!std::isfinite(a)) return InvalidArgument("hatch angles must be finite");
  }
  if (!(tolerance_mm > 0 && std::isfinite(tolerance_mm))) {
    return InvalidArgument("tolerance must be > 0 mm");
  }
  return Status::Ok();
}

namespace {

constexpr int kOutline = 0x000000;
constexpr int kOpen = 0xC0392B;   // open paths: marked once, never filled
constexpr int kHatch = 0x5DADE2;  // the fill

// The preview: the drawing at scale on white, the hatch under the outlines, a 10 mm (or
// decade) scale bar and the extents written under it. y up in the drawing, down in the
// picture.
Status WritePreview(const PatternInspection& in, const std::vector<pattern::Segment2>& hatch,
                    const std::string& path) {
  const Eigen::Vector2d size = (in.hi - in.lo).cwiseMax(1e-3);
  // About 1200 px along the longer side, no more than 100 px per mm (a hatch 0.04 mm apart
  // then still shows as lines on a small part); a drawing of metres (or one read in the wrong
  // units, which is what this is for) gets fewer.
  const double px_per_mm = std::min(1200.0 / std::max(size.x(), size.y()), 100.0);
  const int margin = 40, footer = 60;
  const int w = static_cast<int>(std::ceil(size.x() * px_per_mm)) + 2 * margin;
  const int h = static_cast<int>(std::ceil(size.y() * px_per_mm)) + 2 * margin + footer;
  vision::Canvas canvas(w, h);
  const auto at = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(margin + (p.x() - in.lo.x()) * px_per_mm,
                           margin + (in.hi.y() - p.y()) * px_per_mm);
  };
  for (const pattern::Segment2& s : hatch) canvas.Line(at(s.a), at(s.b), {kHatch, 1, false});
  for (const pattern::Polyline& p : in.pattern.paths) {
    const int colour = p.closed ? kOutline : kOpen;
    for (size_t k = 1; k < p.points.size(); ++k) {
      canvas.Line(at(p.points[k - 1]), at(p.points[k]), {colour, 1, true});
    }
    if (p.closed && p.points.size() > 2) {
      canvas.Line(at(p.points.back()), at(p.points.front()), {colour, 1, true});
    }
  }
  // A scale bar: the longest 1, 2 or 5 x 10^k mm that fits in a third of the width.
  const double room = std::max(size.x() / 3.0, 1e-3);
  const double decade = std::pow(10.0, std::floor(std::log10(room)));
  const double bar_mm = room >= 5 * decade ? 5 * decade : room >= 2 * decade ? 2 * decade : decade;
  const double y_bar = h - footer + 20.0;
  canvas.Line({margin, y_bar}, {margin + bar_mm * px_per_mm, y_bar}, {kOutline, 3, false});
  char text[200];
  std::snprintf(text, sizeof text, "%g mm   extents %.2f x %.2f mm   %d closed, %d open paths",
                bar_mm, in.hi.x() - in.lo.x(), in.hi.y() - in.lo.y(), in.closed_paths,
                in.open_paths);
  canvas.Text(text, {margin, y_bar + 28.0}, 0.5, {kOutline, 1, true});
  return canvas.WritePng(path);
}

}  // namespace

Result<PatternInspection> InspectPattern(const std::string& path,
                                         const PatternInspectOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  PatternInspection in;
  INSITU_ASSIGN_OR_RETURN(in.pattern,
                          pattern::LoadVectorFile(path, options.tolerance_mm / options.scale));
  in.lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  in.hi = -in.lo;
  for (pattern::Polyline& p : in.pattern.paths) {
    for (Eigen::Vector2d& q : p.points) {
      q *= options.scale;
      in.lo = in.lo.cwiseMin(q);
      in.hi = in.hi.cwiseMax(q);
    }
    (p.closed ? in.closed_paths : in.open_paths) += 1;
  }
  if (!(in.hi.x() >= in.lo.x())) in.lo = in.hi = Eigen::Vector2d::Zero();
  for (const pattern::Segment2& s : pattern::Outline(in.pattern)) {
    in.outline_length_mm += (s.b - s.a).norm();
  }
  std::vector<pattern::Segment2> hatch;
  if (in.closed_paths > 0) {
    // The hatch at the job's spacing, unless that is more than 200 000 lines across the
    // drawing: then at the spacing that gives that many, its length scaled back (the area it
    // measures is the same), and a note says so.
    const double diagonal = (in.hi - in.lo).norm();
    const double spacing = std::max(options.hatch_spacing_mm, diagonal / 200000.0);
    if (spacing > options.hatch_spacing_mm) {
      in.pattern.warnings.push_back("the hatch was measured at " + std::to_string(spacing) +
                                    " mm spacing (the drawing spans " +
                                    std::to_string(diagonal) + " mm): its length is scaled");
    }
    for (double angle : options.hatch_angles_deg) {
      INSITU_ASSIGN_OR_RETURN(auto lines, pattern::HatchPolygons(in.pattern, spacing, angle));
      double length = 0.0;
      for (const pattern::Segment2& s : lines) length += (s.b - s.a).norm();
      in.hatch_length_mm += length * spacing / options.hatch_spacing_mm;
      // Each angle fills the same area: the first one measures it.
      if (hatch.empty()) in.filled_area_mm2 = length * spacing;
      hatch.insert(hatch.end(), lines.begin(), lines.end());
    }
  }
  if (!options.preview_path.empty()) {
    INSITU_RETURN_IF_ERROR(WritePreview(in, hatch, options.preview_path));
    in.preview_path = options.preview_path;
  }
  return in;
}

std::string FormatInspection(const std::string& path, const PatternInspection& in) {
  const pattern::VectorPattern& p = in.pattern;
  std::string out;
  char line[400];
  std::snprintf(line, sizeof line, "%s\n  units: %s\n  extents: x %.3f .. %.3f, y %.3f .. %.3f mm (%.3f x %.3f mm)\n",
                path.c_str(), p.units.empty() ? "mm" : p.units.c_str(), in.lo.x(), in.hi.x(),
                in.lo.y(), in.hi.y(), in.hi.x() - in.lo.x(), in.hi.y() - in.lo.y());
  out += line;
  std::snprintf(line, sizeof line,
                "  paths: %d closed (areas to fill), %d open (marked once); outline %.1f mm\n",
                in.closed_paths, in.open_paths, in.outline_length_mm);
  out += line;
  if (in.closed_paths > 0) {
    std::snprintf(line, sizeof line, "  hatch: %.1f mm of lines, filling %.2f mm^2\n",
                  in.hatch_length_mm, in.filled_area_mm2);
    out += line;
  }
  const auto counts = [&](const char* title, const std::map<std::string, int>& m) {
    if (m.empty()) return;
    out += std::string("  ") + title + ":";
    for (const auto& [kind, n] : m) out += " " + kind + " " + std::to_string(n) + ",";
    out.back() = '\n';
  };
  counts("drawn", p.converted);
  counts("skipped", p.skipped);
  if (p.texts > 0) out += "  texts: " + std::to_string(p.texts) + "\n";
  if (p.ignored_commands > 0) {
    out += "  commands without geometry: " + std::to_string(p.ignored_commands) + "\n";
  }
  for (const auto& [kind, n] : p.skipped) {
    out += "warning: " + std::to_string(n) + " " + kind + " not drawn\n";
  }
  for (const std::string& w : p.warnings) out += "warning: " + w + "\n";
  if (!in.preview_path.empty()) out += "  preview: " + in.preview_path + "\n";
  return out;
}

}  // namespace insitu::job
