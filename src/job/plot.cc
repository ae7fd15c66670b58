#include "insitu/job/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <Eigen/Core>

#include "insitu/vision/canvas.h"

namespace insitu::job {
namespace {

constexpr int kWhite = 0xFFFFFF, kBlack = 0x000000;

// A pixel position from integer coordinates.
Eigen::Vector2d Pt(int x, int y) { return Eigen::Vector2d(x, y); }

// A rectangle of pixels [x, x + width) x [y, y + height).
struct Box {
  int x, y, width, height;
};

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
  const Box area{left, top, w - left - right, h - top - bottom};
  vision::Canvas img(w, h, kWhite);
  auto px = [&](double x) {
    return area.x + static_cast<int>(std::lround((x - xr.lo) / (xr.hi - xr.lo) * area.width));
  };
  auto py = [&](double y) {
    return area.y + area.height -
           static_cast<int>(std::lround((y - yr.lo) / (yr.hi - yr.lo) * area.height));
  };
  const vision::Pen black{.rgb = kBlack}, text{.rgb = kBlack, .smooth = true};
  const vision::Pen grid{.rgb = 0xE1E1E1}, grey{.rgb = 0x787878};

  // Grid and tick labels.
  const double xs = NiceStep(xr.hi - xr.lo, 10), ys = NiceStep(yr.hi - yr.lo, 8);
  for (double x = std::ceil(xr.lo / xs) * xs; x <= xr.hi; x += xs) {
    img.Line(Pt(px(x), area.y), Pt(px(x), area.y + area.height), grid);
    const std::string t = Label(x, xs);
    const vision::TextSize sz = vision::Canvas::MeasureText(t, 0.45);
    img.Text(t, Pt(px(x) - sz.width / 2, area.y + area.height + 20), 0.45, text);
  }
  for (double y = std::ceil(yr.lo / ys) * ys; y <= yr.hi; y += ys) {
    img.Line(Pt(area.x, py(y)), Pt(area.x + area.width, py(y)), grid);
    const std::string t = Label(y, ys);
    const vision::TextSize sz = vision::Canvas::MeasureText(t, 0.45);
    img.Text(t, Pt(area.x - sz.width - 8, py(y) + sz.height / 2), 0.45, text);
  }
  img.Rectangle(area.x, area.y, area.width, area.height, black);

  // Reference lines, dashed.
  for (double r : spec.reference_y) {
    if (r < yr.lo || r > yr.hi) continue;
    for (int x = area.x; x < area.x + area.width; x += 12) {
      img.Line(Pt(x, py(r)), Pt(std::min(x + 6, area.x + area.width), py(r)), grey);
    }
  }

  // Series, clipped to the plot area; NaN breaks the line.
  vision::Canvas roi = img.Region(area.x, area.y, area.width, area.height);
  for (const PlotSeries& s : spec.series) {
    const vision::Pen pen{.rgb = s.rgb, .thickness = 2, .smooth = true};
    bool have_prev = false;
    Eigen::Vector2d prev;
    for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) {
        have_prev = false;
        continue;
      }
      const Eigen::Vector2d p = Pt(px(s.x[i]) - area.x, py(s.y[i]) - area.y);
      if (have_prev) roi.Line(prev, p, pen);
      prev = p;
      have_prev = true;
    }
  }

  // Title, axis labels, legend.
  img.Text(spec.title, Pt(left, 35), 0.65, text);
  const vision::TextSize xl = vision::Canvas::MeasureText(spec.x_label, 0.55);
  img.Text(spec.x_label, Pt(area.x + area.width / 2 - xl.width / 2, h - 20), 0.55, text);
  img.Text(spec.y_label, Pt(10, top - 10), 0.5, text);
  // The legend lists the series with a label (an unlabelled series is drawn, not listed).
  std::vector<const PlotSeries*> listed;
  for (const PlotSeries& s : spec.series) {
    if (!s.label.empty()) listed.push_back(&s);
  }
  if (!listed.empty()) {
    int lw = 0;
    for (const PlotSeries* s : listed) {
      lw = std::max(lw, vision::Canvas::MeasureText(s->label, 0.45).width);
    }
    const int lh = 20 * static_cast<int>(listed.size()) + 10;
    const Box box{area.x + area.width - lw - 60, area.y + 10, lw + 50, lh};
    img.Rectangle(box.x, box.y, box.width, box.height,
                  {.rgb = kWhite, .thickness = vision::kFill});
    img.Rectangle(box.x, box.y, box.width, box.height, grey);
    for (size_t i = 0; i < listed.size(); ++i) {
      const int y = box.y + 18 + 20 * static_cast<int>(i);
      img.Line(Pt(box.x + 8, y - 4), Pt(box.x + 32, y - 4),
               {.rgb = listed[i]->rgb, .thickness = 2, .smooth = true});
      img.Text(listed[i]->label, Pt(box.x + 40, y), 0.45, text);
    }
  }
  return img.WritePng(path);
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
    return Eigen::Vector2d(0.5 * w + (x - cx) * scale, 40 + 0.5 * (h - 80) - (y - cy) * scale);
  };
  vision::Canvas img(w, h, kWhite);
  img.Text(f.title, Pt(20, 28), 0.7, {.rgb = kBlack, .thickness = 2, .smooth = true});
  for (size_t i = 0; i < n; ++i) {
    const bool chk = i < f.check.size() && f.check[i];
    const int c = chk ? 0xd62728 : 0x1f77b4;
    const Eigen::Vector2d a = px(f.x_mm[i], f.y_mm[i]);
    const Eigen::Vector2d b = px(f.x_mm[i] + mag * f.dx_mm[i], f.y_mm[i] + mag * f.dy_mm[i]);
    img.Circle(a, 3, {.rgb = c, .thickness = vision::kFill, .smooth = true});
    if ((b - a).norm() > 1.0) img.Arrow(a, b, {.rgb = c, .thickness = 2, .smooth = true}, 0.25);
  }
  // Scale bar: a round error in um, drawn at the magnification.
  const double bar_mm = NiceStep(max_err > 0 ? max_err : 1e-3, 1);
  const Eigen::Vector2d s0(margin, h - 30.0);
  const Eigen::Vector2d s1 = s0 + Eigen::Vector2d(bar_mm * mag * scale, 0);
  img.Line(s0, s1, {.rgb = kBlack, .thickness = 3, .smooth = true});
  char text[160];
  std::snprintf(text, sizeof text, "%g um error (arrows x%.0f); blue: grid, red: check points; largest %.1f um",
                bar_mm * 1e3, mag, max_err * 1e3);
  img.Text(text, Pt(static_cast<int>(s1.x()) + 12, static_cast<int>(s0.y()) + 6), 0.5,
           {.rgb = kBlack, .smooth = true});
  return img.WritePng(path);
}

}  // namespace insitu::job
