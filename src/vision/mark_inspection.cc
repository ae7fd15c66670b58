#include "insitu/vision/mark_inspection.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "vision/image_cv.h"

namespace insitu::vision {
namespace {

double Pixel(const ImageView& im, int u, int v) {
  u = std::clamp(u, 0, im.width - 1);
  v = std::clamp(v, 0, im.height - 1);
  return im.is_8bit() ? im.row8(v)[u] : im.row16(v)[u];
}

double Bilinear(const ImageView& im, double u, double v) {
  const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
  const double a = u - u0, b = v - v0;
  return (1 - b) * ((1 - a) * Pixel(im, u0, v0) + a * Pixel(im, u0 + 1, v0)) +
         b * ((1 - a) * Pixel(im, u0, v0 + 1) + a * Pixel(im, u0 + 1, v0 + 1));
}

// Vertex of the least-squares parabola y = a x^2 + b x + c through (x, y);
// false if it opens the wrong way (sign > 0: a minimum is wanted, a > 0).
bool ParabolaVertex(const std::vector<double>& x, const std::vector<double>& y, double sign,
                    double* vertex) {
  if (x.size() < 3) return false;
  Eigen::MatrixXd a(x.size(), 3);
  Eigen::VectorXd b(x.size());
  for (size_t i = 0; i < x.size(); ++i) {
    a.row(i) << x[i] * x[i], x[i], 1.0;
    b(i) = y[i];
  }
  const Eigen::Vector3d p = a.colPivHouseholderQr().solve(b);
  if (!(sign * p(0) > 0)) return false;
  *vertex = -p(1) / (2.0 * p(0));
  return std::isfinite(*vertex);
}

}  // namespace

Status HatchMeasureOptions::Validate() const {
  if (!(pixel_um > 0)) return InvalidArgument("pixel_um must be > 0");
  if (!(spacing_um > 0)) return InvalidArgument("spacing_um must be > 0");
  if (!(half_length_um > 0) || !(half_width_um > 0)) {
    return InvalidArgument("half_length_um and half_width_um must be > 0");
  }
  if (half_width_um < 1.5 * spacing_um) {
    return InvalidArgument("half_width_um must span at least three lines (>= 1.5 spacings)");
  }
  return Status::Ok();
}

Result<HatchMeasurement> MeasureHatch(const ImageView& im, const HatchMeasureOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  INSITU_RETURN_IF_ERROR(CheckImageView(im, "hatch: "));
  if (im.width < 4 || im.height < 4) return InvalidArgument("hatch: image under 4 x 4 pixels");
  // Directions in the image (pixels per um): galvo g -> (du, -dv) =
  // R(-rotation) g.
  const double rot = o.camera_rotation_deg * M_PI / 180.0, th = o.hatch_angle_deg * M_PI / 180.0;
  const auto to_image = [&](const Eigen::Vector2d& g) -> Eigen::Vector2d {
    const Eigen::Vector2d r(std::cos(rot) * g.x() + std::sin(rot) * g.y(),
                            -std::sin(rot) * g.x() + std::cos(rot) * g.y());
    return Eigen::Vector2d(r.x(), -r.y()) / o.pixel_um;
  };
  const Eigen::Vector2d along = to_image({std::cos(th), std::sin(th)});
  const Eigen::Vector2d across = to_image({-std::sin(th), std::cos(th)});
  for (double s : {-1.0, 1.0}) {
    for (double t : {-1.0, 1.0}) {
      const Eigen::Vector2d c =
          o.centre_px + s * o.half_length_um * along + t * o.half_width_um * across;
      if (c.x() < 0 || c.y() < 0 || c.x() > im.width - 1 || c.y() > im.height - 1) {
        return InvalidArgument("the measured rectangle leaves the image");
      }
    }
  }
  double unmarked = o.unmarked_level;
  if (!std::isfinite(unmarked)) {
    // The bare surface: the 99th percentile of the image (the brightest real
    // pixels, not the single hottest one).
    std::vector<double> all;
    for (int v = 0; v < im.height; v += 2) {
      for (int u = 0; u < im.width; u += 2) all.push_back(Pixel(im, u, v));
    }
    std::nth_element(all.begin(), all.begin() + static_cast<long>(0.99 * (all.size() - 1)),
                     all.end());
    unmarked = all[static_cast<size_t>(0.99 * (all.size() - 1))];
  }

  // The profile across the lines, every quarter pixel, averaged along them
  // every pixel.
  const double step_um = 0.25 * o.pixel_um;
  const int n = static_cast<int>(std::floor(o.half_width_um / step_um));
  const int m = static_cast<int>(std::floor(o.half_length_um / o.pixel_um));
  std::vector<double> t_um(2 * n + 1), prof(2 * n + 1);
  for (int i = -n; i <= n; ++i) {
    double sum = 0.0;
    for (int k = -m; k <= m; ++k) {
      const Eigen::Vector2d p = o.centre_px + (i * step_um) * across + (k * o.pixel_um) * along;
      sum += Bilinear(im, p.x(), p.y());
    }
    t_um[i + n] = i * step_um;
    prof[i + n] = sum / (2 * m + 1);
  }
  const double darkest = *std::min_element(prof.begin(), prof.end());
  if (!(unmarked - darkest > 3.0)) {
    return FailedPrecondition("no marked lines in the measured rectangle (contrast " +
                              std::to_string(unmarked - darkest) + " grey levels)");
  }
  // Line candidates: the darkest sample within +-0.4 spacing, clearly below the
  // bare level.
  const int win = std::max(2, static_cast<int>(0.4 * o.spacing_um / step_um));
  const int fit = std::max(2, static_cast<int>(0.25 * o.spacing_um / step_um));
  const int edge = static_cast<int>(0.5 * o.spacing_um / step_um);
  std::vector<double> centres, depth_at;
  for (int i = edge; i < static_cast<int>(prof.size()) - edge; ++i) {
    const int lo = std::max(0, i - win), hi = std::min<int>(prof.size() - 1, i + win);
    if (prof[i] > unmarked - 0.15 * (unmarked - darkest)) continue;
    if (*std::min_element(prof.begin() + lo, prof.begin() + hi + 1) < prof[i]) continue;
    if (!centres.empty() && t_um[i] - centres.back() < 0.5 * o.spacing_um) continue;  // a tie
    std::vector<double> x, y;
    for (int k = std::max(0, i - fit); k <= std::min<int>(prof.size() - 1, i + fit); ++k) {
      x.push_back(t_um[k] - t_um[i]);
      y.push_back(prof[k]);
    }
    double vertex;
    if (!ParabolaVertex(x, y, 1.0, &vertex) || std::abs(vertex) > fit * step_um) continue;
    centres.push_back(t_um[i] + vertex);
    depth_at.push_back(prof[i]);
  }
  if (centres.size() < 3) {
    return FailedPrecondition("fewer than 3 marked lines found (" + std::to_string(centres.size()) +
                              ")");
  }
  HatchMeasurement out;
  out.lines = static_cast<int>(centres.size());
  out.centres_um = centres;
  std::vector<double> gaps;
  for (size_t i = 1; i < centres.size(); ++i) {
    const double g = centres[i] - centres[i - 1];
    if (g < 1.5 * o.spacing_um) gaps.push_back(g);  // a longer gap is a missing line
  }
  if (gaps.size() < 2) return FailedPrecondition("fewer than 3 neighbouring lines found");
  const double mean = std::accumulate(gaps.begin(), gaps.end(), 0.0) / gaps.size();
  double var = 0.0;
  for (double g : gaps) var += (g - mean) * (g - mean);
  out.spacing_um = mean;
  out.spacing_std_um = std::sqrt(var / (gaps.size() - 1));
  double depth_sum = 0.0;
  for (double d : depth_at) depth_sum += unmarked - d;
  out.contrast = depth_sum / depth_at.size() / std::max(unmarked, 1.0);

  // Widths where the profile between lines comes back near the bare level.
  const auto sample_of = [&](double t) { return static_cast<int>(std::lround(t / step_um)) + n; };
  bool separated = true;
  std::vector<double> widths;
  for (size_t i = 0; i < centres.size() && separated; ++i) {
    const int c = sample_of(centres[i]);
    const double half = 0.5 * (unmarked + prof[c]);
    const int reach = static_cast<int>(0.75 * o.spacing_um / step_um);
    double edges[2] = {NAN, NAN};
    for (int dir : {-1, 1}) {
      for (int k = 1; k <= reach; ++k) {
        const int a = c + dir * (k - 1), b = c + dir * k;
        if (b < 0 || b >= static_cast<int>(prof.size())) break;
        if (prof[b] >= half) {
          const double f = (half - prof[a]) / (prof[b] - prof[a]);
          edges[dir > 0] = t_um[a] + dir * f * step_um;
          break;
        }
      }
    }
    if (i > 0) {
      const int a = sample_of(centres[i - 1]);
      const double peak = *std::max_element(prof.begin() + a, prof.begin() + c + 1);
      separated = peak > unmarked - 0.3 * (unmarked - std::min(prof[a], prof[c]));
    }
    if (std::isfinite(edges[0]) && std::isfinite(edges[1])) widths.push_back(edges[1] - edges[0]);
  }
  out.separated = separated && widths.size() >= 3;
  if (out.separated) {
    const double w = std::accumulate(widths.begin(), widths.end(), 0.0) / widths.size();
    double wv = 0.0;
    for (double x : widths) wv += (x - w) * (x - w);
    out.width_um = w;
    out.width_std_um = std::sqrt(wv / (widths.size() - 1));
  }
  return out;
}

double Sharpness(const ImageView& im, const Eigen::Vector2d& centre, int half) {
  const int u0 = std::max(1, static_cast<int>(centre.x()) - half);
  const int u1 = std::min(im.width - 2, static_cast<int>(centre.x()) + half);
  const int v0 = std::max(1, static_cast<int>(centre.y()) - half);
  const int v1 = std::min(im.height - 2, static_cast<int>(centre.y()) + half);
  double sum = 0.0;
  long count = 0;
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) {
      const double gx = 0.5 * (Pixel(im, u + 1, v) - Pixel(im, u - 1, v));
      const double gy = 0.5 * (Pixel(im, u, v + 1) - Pixel(im, u, v - 1));
      sum += gx * gx + gy * gy;
      ++count;
    }
  }
  return count > 0 ? sum / count : 0.0;
}

Result<double> BestFocus(const std::vector<double>& z, const std::vector<double>& sharp) {
  if (z.size() != sharp.size() || z.size() < 3) {
    return InvalidArgument("a focus sweep needs at least 3 (z, sharpness) samples");
  }
  const size_t k = std::max_element(sharp.begin(), sharp.end()) - sharp.begin();
  if (k == 0 || k + 1 == z.size()) {
    return FailedPrecondition("the sharpest image is at the end of the focus sweep (z = " +
                              std::to_string(z[k]) + " mm): the focus lies outside it");
  }
  std::vector<double> x, y;
  for (size_t i = (k >= 2 ? k - 2 : 0); i <= std::min(z.size() - 1, k + 2); ++i) {
    if (!(sharp[i] > 0)) continue;
    x.push_back(z[i] - z[k]);
    y.push_back(std::log(sharp[i]));
  }
  double vertex;
  if (!ParabolaVertex(x, y, -1.0, &vertex) || std::abs(vertex) > std::abs(z[k + 1] - z[k - 1])) {
    return FailedPrecondition("the focus curve has no clear peak");
  }
  return z[k] + vertex;
}

}  // namespace insitu::vision
