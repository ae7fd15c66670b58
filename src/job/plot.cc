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
  if (!spec.series.empty()) {
    int lw = 0;
    for (const PlotSeries& s : spec.series) {
      lw = std::max(lw, cv::getTextSize(s.label, font, 0.45, 1, &base).width);
    }
    const int lh = 20 * static_cast<int>(spec.series.size()) + 10;
    const cv::Rect box(area.x + area.width - lw - 60, area.y + 10, lw + 50, lh);
    cv::rectangle(img, box, cv::Scalar(255, 255, 255), cv::FILLED);
    cv::rectangle(img, box, grey, 1);
    for (size_t i = 0; i < spec.series.size(); ++i) {
      const int y = box.y + 18 + 20 * static_cast<int>(i);
      cv::line(img, {box.x + 8, y - 4}, {box.x + 32, y - 4}, Bgr(spec.series[i].rgb), 2,
               cv::LINE_AA);
      cv::putText(img, spec.series[i].label, {box.x + 40, y}, font, 0.45, black, 1, cv::LINE_AA);
    }
  }
  try {
    if (!cv::imwrite(path, img)) return DeviceError("cannot write plot " + path);
  } catch (const cv::Exception& e) {
    return DeviceError("cannot write plot " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace insitu::job
