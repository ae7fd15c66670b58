#include "insitu/job/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace insitu::job {
namespace {

cv::Scalar Bgr(int rgb) { return cv::Scalar(rgb & 0xFF, (rgb >> 8) & 0xFF, (rgb >> 16) & 0xFF); }

// Tick step of 1, 2 or 5 x 10^k giving about `target` ticks over `range`.
double NiceStep(double range, int target) {
  const double raw = range / std::max(1, target);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (raw <= m * mag) return m * mag;
  }
  return 10.0 * mag;
}

std::string Label(double v, double step) {
  if (std::abs(v) < step * 1e-6) v = 0.0;
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool empty() const { return !(lo <= hi); }
  void Pad(double fraction) {
    if (empty()) {
      lo = 0.0;
      hi = 1.0;
    }
    if (hi - lo < 1e-12) {
      const double d = std::max(std::abs(lo) * 0.1, 1e-3);
      lo -= d;
      hi += d;
    }
    const double m = (hi - lo) * fraction;
    lo -= m;
    hi += m;
  }
};

}  // namespace

int PlotColor(int i) {
  static const int kPalette[] = {0x1f77b4, 0xd62728, 0x2ca02c, 0xff7f0e,
                                 0x9467bd, 0x8c564b, 0xe377c2, 0x17becf};
  return kPalette[((i % 8) + 8) % 8];
}

Status SavePlotPng(const PlotSpec& spec, const std::string& path) {
  if (path.size() < 4 || path.substr(path.size() - 4) != ".png") {
    return InvalidArgument("plot path must end in .png: " + path);
  }
  if (spec.width_px < 200 || spec.height_px < 200) {
    return InvalidArgument("plot size must be at least 200 x 200 px");
  }
  Range xr, yr;
  for (const PlotSeries& s : spec.series) {
    for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      xr.Add(s.x[i]);
      yr.Add(s.y[i]);
    }
  }
  for (double r : spec.reference_y) yr.Add(r);
  xr.Pad(0.02);
  if (spec.y_range) {
    yr.lo = spec.y_range->first;
    yr.hi = spec.y_range->second;
  } else {
    yr.Pad(0.08);
  }

  const int w = spec.width_px, h = spec.height_px;
  const int left = 90, right = 30, top = 60, bottom = 70;
  const cv::Rect area(left, top, w - left - right, h - top - bottom);
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  auto px = [&](double x) {
    return area.x + static_cast<int>(std::lround((x - xr.lo) / (xr.hi - xr.lo) * area.width));
  };
  auto py = [&](double y) {
    return area.y + area.height -
           static_cast<int>(std::lround((y - yr.lo) / (yr.hi - yr.lo) * area.height));
  };
  const cv::Scalar black(0, 0, 0), grid(225, 225, 225), grey(120, 120, 120);
  const int font = cv::FONT_HERSHEY_SIMPLEX;

  // Grid and tick labels.
  const double xs = NiceStep(xr.hi - xr.lo, 10), ys = NiceStep(yr.hi - yr.lo, 8);
  for (double x = std::ceil(xr.lo / xs) * xs; x <= xr.hi; x += xs) {
    cv::line(img, {px(x), area.y}, {px(x), area.y + area.height}, grid, 1);
    const std::string t = Label(x, xs);
    int base = 0;
    const cv::Size sz = cv::getTextSize(t, font, 0.45, 1, &base);
    cv::putText(img, t, {px(x) - sz.width / 2, area.y + area.height + 20}, font, 0.45, black, 1,
                cv::LINE_AA);
  }
  for (double y = std::ceil(yr.lo / ys) * ys; y <= yr.hi; y += ys) {
    cv::line(img, {area.x, py(y)}, {area.x + area.width, py(y)}, grid, 1);
    const std::string t = Label(y, ys);
    int base = 0;
    const cv::Size sz = cv::getTextSize(t, font, 0.45, 1, &base);
    cv::putText(img, t, {area.x - sz.width - 8, py(y) + sz.height / 2}, font, 0.45, black, 1,
                cv::LINE_AA);
  }
  cv::rectangle(img, area, black, 1);

  // Reference lines, dashed.
  for (double r : spec.reference_y) {
    if (r < yr.lo || r > yr.hi) continue;
    for (int x = area.x; x < area.x + area.width; x += 12) {
      cv::line(img, {x, py(r)}, {std::min(x + 6, area.x + area.width), py(r)}, grey, 1);
    }
  }

  // Series, clipped to the plot area; NaN breaks the line.
  cv::Mat roi = img(area);
  for (const PlotSeries& s : spec.series) {
    const cv::Scalar c = Bgr(s.rgb);
    bool have_prev = false;
    cv::Point prev;
    for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) {
        have_prev = false;
        continue;
      }
      const cv::Point p(px(s.x[i]) - area.x, py(s.y[i]) - area.y);
      if (have_prev) cv::line(roi, prev, p, c, 2, cv::LINE_AA);
      prev = p;
      have_prev = true;
    }
  }

  // Title, axis labels, legend.
  cv::putText(img, spec.title, {left, 35}, font, 0.65, black, 1, cv::LINE_AA);
  int base = 0;
  const cv::Size xl = cv::getTextSize(spec.x_label, font, 0.55, 1, &base);
  cv::putText(img, spec.x_label, {area.x + area.width / 2 - xl.width / 2, h - 20}, font, 0.55,
              black, 1, cv::LINE_AA);
  cv::putText(img, spec.y_label, {10, top - 10}, font, 0.5, black, 1, cv::LINE_AA);
  // The legend lists the series with a label (an unlabelled series is drawn, not listed).
  std::vector<const PlotSeries*> listed;
  for (const PlotSeries& s : spec.series) {
    if (!s.label.empty()) listed.push_back(&s);
  }
  if (!listed.empty()) {
    int lw = 0;
    for (const PlotSeries* s : listed) {
      lw = std::max(lw, cv::getTextSize(s->label, font, 0.45, 1, &base).width);
    }
    const int lh = 20 * static_cast<int>(listed.size()) + 10;
    const cv::Rect box(area.x + area.width - lw - 60, area.y + 10, lw + 50, lh);
    cv::rectangle(img, box, cv::Scalar(255, 255, 255), cv::FILLED);
    cv::rectangle(img, box, grey, 1);
    for (size_t i = 0; i < listed.size(); ++i) {
      const int y = box.y + 18 + 20 * static_cast<int>(i);
      cv::line(img, {box.x + 8, y - 4}, {box.x + 32, y - 4}, Bgr(listed[i]->rgb), 2, cv::LINE_AA);
      cv::putText(img, listed[i]->label, {box.x + 40, y}, font, 0.45, black, 1, cv::LINE_AA);
    }
  }
  try {
    if (!cv::imwrite(path, img)) return DeviceError("cannot write plot " + path);
  } catch (const cv::Exception& e) {
    return DeviceError("cannot write plot " + path + ": " + e.what());
  }
  return Status::Ok();
}

Status SaveFieldArrowsPng(const FieldArrows& f, const std::string& path) {
  const size_t n = f.x_mm.size();
  if (f.y_mm.size() != n || f.dx_mm.size() != n || f.dy_mm.size() != n) {
    return InvalidArgument("field arrows: x, y, dx and dy must have the same length");
  }
  if (n == 0) return InvalidArgument("field arrows: no targets");
  Range rx, ry;
  double max_err = 0;
  for (size_t i = 0; i < n; ++i) {
    rx.Add(f.x_mm[i]);
    ry.Add(f.y_mm[i]);
    max_err = std::max(max_err, std::hypot(f.dx_mm[i], f.dy_mm[i]));
  }
  const double span = std::max(rx.hi - rx.lo, ry.hi - ry.lo);
  const double cell = span / std::max(1.0, std::sqrt(static_cast<double>(n)) - 1.0);
  double mag = f.magnification;
  if (!(mag > 0)) mag = max_err > 0 ? 0.8 * cell / max_err : 1.0;
  const int w = f.size_px, h = f.size_px + 80;
  const double margin = 60, scale = (w - 2 * margin) / std::max(span + cell, 1e-9);
  const double cx = 0.5 * (rx.lo + rx.hi), cy = 0.5 * (ry.lo + ry.hi);
  // Galvo y up, image v down.
  const auto px = [&](double x, double y) {
    return cv::Point2d(0.5 * w + (x - cx) * scale, 40 + 0.5 * (h - 80) - (y - cy) * scale);
  };
  try {
    cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
    cv::putText(img, f.title, {20, 28}, cv::FONT_HERSHEY_SIMPLEX, 0.7, {0, 0, 0}, 2, cv::LINE_AA);
    for (size_t i = 0; i < n; ++i) {
      const bool chk = i < f.check.size() && f.check[i];
      const cv::Scalar c = chk ? Bgr(0xd62728) : Bgr(0x1f77b4);
      const cv::Point2d a = px(f.x_mm[i], f.y_mm[i]);
      const cv::Point2d b = px(f.x_mm[i] + mag * f.dx_mm[i], f.y_mm[i] + mag * f.dy_mm[i]);
      cv::circle(img, a, 3, c, cv::FILLED, cv::LINE_AA);
      if (cv::norm(b - a) > 1.0) cv::arrowedLine(img, a, b, c, 2, cv::LINE_AA, 0, 0.25);
    }
    // Scale bar: a round error in um, drawn at the magnification.
    const double bar_mm = NiceStep(max_err > 0 ? max_err : 1e-3, 1);
    const cv::Point2d s0(margin, h - 30.0);
    const cv::Point2d s1 = s0 + cv::Point2d(bar_mm * mag * scale, 0);
    cv::line(img, s0, s1, {0, 0, 0}, 3, cv::LINE_AA);
    char text[160];
    std::snprintf(text, sizeof text, "%g um error (arrows x%.0f); blue: grid, red: check points; largest %.1f um",
                  bar_mm * 1e3, mag, max_err * 1e3);
    cv::putText(img, text, {static_cast<int>(s1.x) + 12, static_cast<int>(s0.y) + 6},
                cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1, cv::LINE_AA);
    if (!cv::imwrite(path, img)) return DeviceError("cannot write " + path);
  } catch (const cv::Exception& e) {
    return DeviceError("cannot write " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace insitu::job
