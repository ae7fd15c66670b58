#include "job/insert_picture.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "insitu/vision/canvas.h"

namespace insitu::job {

Status SaveInsertPicture(const geometry::Cloud& cloud, const inspect::InsertResult& r,
                         const inspect::InsertSpec& spec, const std::string& path) {
  // Frame: the corners plus a margin, 40 px per mm.
  Eigen::Vector2d lo = r.corners_mm[0], hi = r.corners_mm[0];
  for (const auto& c : r.corners_mm) {
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  lo -= Eigen::Vector2d(2.0, 2.0);
  hi += Eigen::Vector2d(2.0, 2.0);
  constexpr double kScale = 40.0;
  const int top_margin = 70;
  const int w = static_cast<int>((hi.x() - lo.x()) * kScale);
  const int h = static_cast<int>((hi.y() - lo.y()) * kScale) + top_margin;
  vision::Canvas img(w, h);
  // +y up in the picture, as seen from above; whole pixels.
  auto px = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(static_cast<int>(std::lround((p.x() - lo.x()) * kScale)),
                           top_margin + static_cast<int>(std::lround((hi.y() - p.y()) * kScale)));
  };
  const double z0 = r.plate_z_mm, z1 = r.plate_z_mm + 1.1 * spec.thickness_mm;
  for (const auto& p : cloud) {
    const Eigen::Vector2d q(p.point_in_galvo.x(), p.point_in_galvo.y());
    if ((q.array() < lo.array()).any() || (q.array() > hi.array()).any()) continue;
    const double t = std::clamp((p.point_in_galvo.z() - z0) / (z1 - z0), 0.0, 1.0);
    const int g = static_cast<int>(225 - 160 * t);
    img.Circle(px(q), 1, {.rgb = g << 16 | g << 8 | g, .thickness = vision::kFill});
  }
  for (const auto& q : r.outline_points) img.Circle(px(q), 2, {.rgb = 0x005AC8});
  for (const auto& q : r.hole_points_mm) img.Circle(px(q), 2, {.rgb = 0x009600});
  const vision::Pen red{.rgb = 0xDC0000, .smooth = true};
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector2d& a = r.corners_mm[(i + 2) % 3];
    const Eigen::Vector2d& b = r.corners_mm[i];
    img.Line(px(a), px(b), red);
    char label[64];
    std::snprintf(label, sizeof label, "L%d %.3f", i + 1, r.edge_mm[i]);
    const Eigen::Vector2d mid = 0.5 * (a + b);
    const Eigen::Vector2d centre = (r.corners_mm[0] + r.corners_mm[1] + r.corners_mm[2]) / 3.0;
    const Eigen::Vector2d at = mid + 1.2 * (mid - centre).normalized();
    img.Text(label, px(at) - Eigen::Vector2d(50, 0), 0.5, red);
  }
  img.Circle(px(r.hole_center_mm), static_cast<int>(0.5 * r.hole_diameter_mm * kScale), red);
  char text[200];
  std::snprintf(text, sizeof text, "insert: thickness %.3f mm, hole D %.3f mm", r.thickness_mm,
                r.hole_diameter_mm);
  img.Text(text, Eigen::Vector2d(10, 25), 0.55, {.rgb = 0x000000, .smooth = true});
  std::snprintf(text, sizeof text,
                "nominal %.2f / %.2f / %.2f mm; blue: outline, green: hole edge points",
                spec.thickness_mm, spec.edge_mm, spec.hole_diameter_mm);
  img.Text(text, Eigen::Vector2d(10, 50), 0.45, {.rgb = 0x3C3C3C, .smooth = true});
  return img.WritePng(path);
}

}  // namespace insitu::job
