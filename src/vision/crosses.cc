// "+" crosses of a reticle (seed 001 sec. 3.3, 4.2).
//
// Finding them. The field behind the crosses may drift (illumination falls off toward the
// image edge), so the background is the morphological opening of the frame with a window
// wider than any line: the opening removes the lines and keeps the field. What stands above
// it by more than half the least contrast asked for (or 5 noise sigmas, the noise measured
// robustly on the same difference) is labelled; one cross is one connected blob. The blob's
// orientation comes from its fourth angular moment (sum of w r^2 e^{4i phi}): a "+" is
// isotropic in its second moments, but its fourth harmonic points along its bars.
//
// Measuring them (the centre). Each bar is measured on the raw frame, not on the filtered
// one: for the bar nearer to the image's u axis, one sample per column u; for the other one
// per row v. A sample is the gray-level centroid, above the cross's local background (the
// median of the non-line pixels around it), of a window held symmetric about the current
// line estimate (the end pixels weighted by the fraction of them inside), so a background
// left over after subtraction pulls on both sides alike and the centroid stays unbiased.
// A line (v = v0 + m u, or u = u0 + m v) is fitted to the centres by least squares, the
// windows re-centred on it, and fitted again; samples near the cross's middle (where the
// other bar runs through the window) and near the bar's tips (where the profile fades) are
// left out. The centre is where the two lines meet.
//
// Precision, for the coaxial camera on the reticle (9 um lines, 5 um pixels, diffraction
// sigma 4.3 um): the line image has sigma ~1 px, so pixel sampling biases a centroid by a
// negligible amount (the Fourier term of a sampled Gaussian at 1 / px, exp(-2 pi^2 sigma^2),
// ~3e-9 px); shot noise of ~2 gray levels at a ~140 level peak gives ~0.03 px per centroid,
// and ~70 samples per line ~0.005 px at the centre.
#include "insitu/vision/crosses.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "vision/image_cv.h"

namespace insitu::vision {
namespace {

std::string Format(const char* fmt, double a, double b = 0.0) {
  char buf[200];
  std::snprintf(buf, sizeof buf, fmt, a, b);
  return buf;
}



// One bar's line in its own axes: b = b0 + m (a - a_ref), with (a, b) = (u, v) for a bar
// nearer to u, (v, u) for the other.
struct BarLine {
  bool along_u = true;
  double a_ref = 0.0, b0 = 0.0, m = 0.0;
  double ss_residual = 0.0;  // sum of squared perpendicular residuals, px^2
  int samples = 0;
  double peak = 0.0;  // median line peak over the background

  Eigen::Vector2d Point() const {
    return along_u ? Eigen::Vector2d(a_ref, b0) : Eigen::Vector2d(b0, a_ref);
  }
  Eigen::Vector2d Direction() const {
    const Eigen::Vector2d d = along_u ? Eigen::Vector2d(1.0, m) : Eigen::Vector2d(m, 1.0);
    return d.normalized();
  }
};

struct Sample {
  double a = 0.0, b = 0.0, peak = 0.0;
};

// Measures one bar through `centre` with unit direction `dir`, from `t_lo` to `t_hi` along
// it (px from the centre, t_lo < 0 < t_hi), leaving out |t| < clear. False if too few
// samples carry the line.
bool MeasureBar(const cv::Mat& raw, double background, const Eigen::Vector2d& centre,
                const Eigen::Vector2d& dir, double t_lo, double t_hi, double clear,
                double half_window, double min_peak, BarLine* line) {
  const bool along_u = std::abs(dir.x()) >= std::abs(dir.y());
  const double da = along_u ? dir.x() : dir.y(), db = along_u ? dir.y() : dir.x();
  const double ca = along_u ? centre.x() : centre.y(), cb = along_u ? centre.y() : centre.x();
  // The profile along b is the line's profile stretched by 1 / |da|.
  const double h = half_window / std::abs(da);
  const int a_max = along_u ? raw.cols - 1 : raw.rows - 1;
  const int b_max = along_u ? raw.rows - 1 : raw.cols - 1;
  line->along_u = along_u;
  line->a_ref = ca;
  line->b0 = cb;
  line->m = db / da;
  // a range of the two stretches of the bar, in this bar's primary coordinate.
  const double a0 = ca + std::min(t_lo * da, t_hi * da), a1 = ca + std::max(t_lo * da, t_hi * da);
  const double a_clear = clear * std::abs(da);
  std::vector<Sample> samples;
  for (int iteration = 0; iteration < 3; ++iteration) {
    samples.clear();
    for (int a = std::max(0, static_cast<int>(std::ceil(a0)));
         a <= std::min(a_max, static_cast<int>(std::floor(a1))); ++a) {
      if (std::abs(a - ca) < a_clear) continue;
      const double b_pred = line->b0 + line->m * (a - line->a_ref);
      const int b_lo = static_cast<int>(std::floor(b_pred - h - 0.5));
      const int b_hi = static_cast<int>(std::ceil(b_pred + h + 0.5));
      if (b_lo < 0 || b_hi > b_max) continue;
      double sum = 0.0, moment = 0.0, peak = 0.0;
      for (int b = b_lo; b <= b_hi; ++b) {
        const double weight = std::clamp(h + 0.5 - std::abs(b - b_pred), 0.0, 1.0);
        if (weight <= 0.0) continue;
        const float value = along_u ? raw.at<float>(b, a) : raw.at<float>(a, b);
        const double g = std::max(0.0, value - background);
        peak = std::max(peak, g);
        sum += weight * g;
        moment += weight * g * b;
      }
      if (peak < min_peak || sum <= 0.0) continue;
      samples.push_back({static_cast<double>(a), moment / sum, peak});
    }
    if (samples.size() < 6) return false;
    // Least squares b = b0 + m (a - a_ref); from the 2nd pass on, samples far off the line
    // (a dust speck, the other bar's halo) are left out: 4 robust sigmas, at least 0.3 px.
    std::vector<float> residuals;
    for (const Sample& s : samples) {
      residuals.push_back(static_cast<float>(std::abs(s.b - line->b0 - line->m * (s.a - ca))));
    }
    const double limit = iteration == 0 ? 1e9 : std::max(0.3, 4.0 * kMadToSigma * MedianInPlace(residuals));
    double s0 = 0, s1 = 0, s2 = 0, sb = 0, sab = 0;
    for (const Sample& s : samples) {
      if (iteration > 0 && std::abs(s.b - line->b0 - line->m * (s.a - ca)) > limit) continue;
      const double x = s.a - ca;
      s0 += 1;
      s1 += x;
      s2 += x * x;
      sb += s.b;
      sab += x * s.b;
    }
    const double det = s0 * s2 - s1 * s1;
    if (s0 < 6 || det <= 1e-9) return false;
    const double m = (s0 * sab - s1 * sb) / det;
    const double b0 = (sb - m * s1) / s0;
    const double old_b0 = line->b0, old_m = line->m;
    line->b0 = b0;
    line->m = m;
    if (iteration == 2 ||
        (iteration > 0 && std::abs(b0 - old_b0) < 1e-4 && std::abs(m - old_m) < 1e-6)) {
      line->ss_residual = 0.0;
      line->samples = 0;
      std::vector<float> peaks;
      const double cos2 = 1.0 / (1.0 + m * m);
      for (const Sample& s : samples) {
        const double r = s.b - b0 - m * (s.a - ca);
        if (std::abs(r) > limit) continue;
        line->ss_residual += r * r * cos2;
        ++line->samples;
        peaks.push_back(static_cast<float>(s.peak));
      }
      line->peak = peaks.empty() ? 0.0 : MedianInPlace(peaks);
      return line->samples >= 6;
    }
  }
  return false;
}

}  // namespace

Status CrossOptions::Validate() const {
  if (!(max_line_width_px >= 1.0 && max_line_width_px <= 200.0)) {
    return InvalidArgument(
        Format("crosses: max_line_width_px %.6g not in [1, 200]", max_line_width_px));
  }
  if (!(min_bar_px > 2.0 * max_line_width_px) || !(max_bar_px >= min_bar_px)) {
    return InvalidArgument(
        Format("crosses: need 2 max_line_width_px < min_bar_px <= max_bar_px, got min_bar_px %.6g, "
               "max_bar_px %.6g",
               min_bar_px, max_bar_px));
  }
  if (!(min_contrast_fraction > 0 && min_contrast_fraction <= 1)) {
    return InvalidArgument(
        Format("crosses: min_contrast_fraction %.6g not in (0, 1]", min_contrast_fraction));
  }
  if (border_px < 0) return InvalidArgument(Format("crosses: border_px %.6g < 0", border_px));
  return Status::Ok();
}

Result<std::vector<Cross>> FindCrosses(const ImageView& image, const CrossOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  INSITU_RETURN_IF_ERROR(CheckImageView(image, "crosses: "));
  std::vector<Cross> crosses;
  try {
    cv::Mat raw = ToFloatMat(image);
    if (!o.bright) raw = static_cast<double>(image.max_value()) - raw;

    // Segmentation on a lightly smoothed copy against the opened background.
    cv::Mat smooth;
    cv::GaussianBlur(raw, smooth, cv::Size(3, 3), 0.8, 0.8, cv::BORDER_REPLICATE);
    const int k = 2 * static_cast<int>(std::ceil(o.max_line_width_px)) + 1;
    cv::Mat opened;
    cv::morphologyEx(smooth, opened, cv::MORPH_OPEN,
                     cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)), cv::Point(-1, -1),
                     1, cv::BORDER_REPLICATE);
    cv::blur(opened, opened, cv::Size(k, k), cv::Point(-1, -1), cv::BORDER_REPLICATE);
    const cv::Mat lift = smooth - opened;
    const int step = std::max(1, static_cast<int>(std::sqrt(lift.total() / 20000.0)));
    double median, sigma;
    RobustLevel(lift, step, &median, &sigma);
    const double min_peak = o.min_contrast_fraction * image.max_value();
    const double threshold = median + std::max(5.0 * sigma, 0.5 * min_peak);
    cv::Mat mask = lift > threshold;
    cv::Mat labels, stats, centroids;
    const int n = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);

    const double half_window = 0.5 * o.max_line_width_px + 2.0;
    for (int label = 1; label < n; ++label) {
      const int x0 = stats.at<int>(label, cv::CC_STAT_LEFT);
      const int y0 = stats.at<int>(label, cv::CC_STAT_TOP);
      const int bw = stats.at<int>(label, cv::CC_STAT_WIDTH);
      const int bh = stats.at<int>(label, cv::CC_STAT_HEIGHT);
      if (x0 < o.border_px || y0 < o.border_px || x0 + bw > image.width - o.border_px ||
          y0 + bh > image.height - o.border_px) {
        continue;
      }
      // A turned cross's bounding box is at least its bar's length times cos 45 deg.
      if (std::max(bw, bh) < 0.7 * o.min_bar_px || std::max(bw, bh) > 1.5 * o.max_bar_px) {
        continue;
      }
      // The blob's pixels, weighted by how far they stand out.
      std::vector<Eigen::Vector3d> pixels;  // u, v, weight
      Eigen::Vector2d c0 = Eigen::Vector2d::Zero();
      double total = 0.0;
      for (int v = y0; v < y0 + bh; ++v) {
        const int* row = labels.ptr<int>(v);
        for (int u = x0; u < x0 + bw; ++u) {
          if (row[u] != label) continue;
          const double w = std::max(0.0, static_cast<double>(lift.at<float>(v, u)));
          pixels.emplace_back(u, v, w);
          c0 += w * Eigen::Vector2d(u, v);
          total += w;
        }
      }
      if (total <= 0.0) continue;
      c0 /= total;
      // Orientation from the fourth angular harmonic; a blob without it is no cross.
      std::complex<double> z4 = 0.0;
      double r2_sum = 0.0;
      for (const Eigen::Vector3d& p : pixels) {
        const std::complex<double> z(p.x() - c0.x(), p.y() - c0.y());
        const double r2 = std::norm(z);
        if (r2 < 1e-12) continue;
        const std::complex<double> z2 = z * z;
        z4 += p.z() * z2 * z2 / r2;
        r2_sum += p.z() * r2;
      }
      if (!(r2_sum > 0.0) || std::abs(z4) < 0.3 * r2_sum) continue;
      const double theta = 0.25 * std::arg(z4);  // (-45, 45] deg
      const Eigen::Vector2d d1(std::cos(theta), std::sin(theta)), d2(-d1.y(), d1.x());
      // Each bar's extent: blob pixels within a line width of its axis.
      double lo1 = 0, hi1 = 0, lo2 = 0, hi2 = 0;
      for (const Eigen::Vector3d& p : pixels) {
        const Eigen::Vector2d r(p.x() - c0.x(), p.y() - c0.y());
        const double t1 = r.dot(d1), t2 = r.dot(d2);
        if (std::abs(t2) <= o.max_line_width_px) lo1 = std::min(lo1, t1), hi1 = std::max(hi1, t1);
        if (std::abs(t1) <= o.max_line_width_px) lo2 = std::min(lo2, t2), hi2 = std::max(hi2, t2);
      }
      const double bar1 = hi1 - lo1, bar2 = hi2 - lo2;
      if (std::min(bar1, bar2) < o.min_bar_px || std::max(bar1, bar2) > o.max_bar_px) continue;

      // Local background: the median of the frame around the cross, off its lines.
      std::vector<float> around;
      const int margin = k;
      for (int v = std::max(0, y0 - margin); v < std::min(image.height, y0 + bh + margin); ++v) {
        const uchar* m = mask.ptr<uchar>(v);
        const float* r = raw.ptr<float>(v);
        for (int u = std::max(0, x0 - margin); u < std::min(image.width, x0 + bw + margin); ++u) {
          if (m[u] == 0) around.push_back(r[u]);
        }
      }
      const double background = around.empty() ? 0.0 : MedianInPlace(around);

      // Two rounds: the lines through the blob's centroid, then through their crossing.
      const double clear = 0.5 * o.max_line_width_px + half_window + 1.0;
      const double tip = 0.5 * o.max_line_width_px + 2.0;
      Eigen::Vector2d centre = c0;
      Eigen::Vector2d dir1 = d1, dir2 = d2;
      BarLine l1, l2;
      bool ok = true;
      for (int round = 0; round < 2 && ok; ++round) {
        const Eigen::Vector2d shift = centre - c0;
        ok = MeasureBar(raw, background, centre, dir1, lo1 - shift.dot(d1) + tip,
                        hi1 - shift.dot(d1) - tip, clear, half_window, min_peak, &l1) &&
             MeasureBar(raw, background, centre, dir2, lo2 - shift.dot(d2) + tip,
                        hi2 - shift.dot(d2) - tip, clear, half_window, min_peak, &l2);
        if (!ok) break;
        // Where P1 + s D1 = P2 + t D2.
        const Eigen::Vector2d p1 = l1.Point(), p2 = l2.Point();
        dir1 = l1.Direction();
        dir2 = l2.Direction();
        Eigen::Matrix2d a;
        a.col(0) = dir1;
        a.col(1) = -dir2;
        if (std::abs(a.determinant()) < 0.5) {  // the bars are not near perpendicular
          ok = false;
          break;
        }
        const Eigen::Vector2d st = a.inverse() * (p2 - p1);
        centre = p1 + st.x() * dir1;
      }
      if (!ok) continue;
      Cross cross;
      cross.centre_px = centre;
      cross.angle_deg = std::atan2(dir1.y(), dir1.x()) * 180.0 / M_PI;
      if (cross.angle_deg > 90.0) cross.angle_deg -= 180.0;
      if (cross.angle_deg <= -90.0) cross.angle_deg += 180.0;
      double second = std::atan2(dir2.y(), dir2.x()) * 180.0 / M_PI;
      while (second - cross.angle_deg > 135.0) second -= 180.0;
      while (second - cross.angle_deg <= -45.0) second += 180.0;
      cross.angle2_deg = second;
      cross.bar_px = 0.5 * (bar1 + bar2);
      cross.contrast = 0.5 * (l1.peak + l2.peak);
      cross.background = o.bright ? background : image.max_value() - background;
      cross.samples = l1.samples + l2.samples;
      cross.residual_px = std::sqrt((l1.ss_residual + l2.ss_residual) / cross.samples);
      if (cross.contrast < min_peak) continue;
      crosses.push_back(cross);
    }
  } catch (const cv::Exception& e) {
    return Status(StatusCode::kInternal, std::string("crosses: OpenCV: ") + e.what());
  }
  std::sort(crosses.begin(), crosses.end(), [](const Cross& a, const Cross& b) {
    const long ra = std::lround(a.centre_px.y()), rb = std::lround(b.centre_px.y());
    if (ra != rb) return ra < rb;
    return a.centre_px.x() < b.centre_px.x();
  });
  return crosses;
}

}  // namespace insitu::vision
