// Line plots written as PNG (the figures jobs leave next to their reports), drawn on a
// vision::Canvas. Errors: invalid_argument for a bad spec, device_error naming the file.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::job {

struct PlotSeries {
  std::string label;  // in the legend; empty: drawn, not listed
  std::vector<double> x, y;  // NaN y values break the line
  int rgb = 0x1f77b4;
};

struct PlotSpec {
  std::string title;
  std::string x_label;
  std::string y_label;
  std::vector<PlotSeries> series;
  std::vector<double> reference_y;             // horizontal dashed lines (tolerance bands)
  std::optional<std::pair<double, double>> y_range;  // else from the data
  int width_px = 1100;
  int height_px = 650;
};

Status SavePlotPng(const PlotSpec& spec, const std::string& path);

// A field error map: one arrow per target from where it was asked for (x, y, mm) along its
// error (dx, dy, mm), magnified so the largest is about a grid cell, with a scale bar naming
// the magnification in um. Check points (`check` true) drawn in another colour. All four
// vectors the same length.
struct FieldArrows {
  std::string title;
  std::vector<double> x_mm, y_mm, dx_mm, dy_mm;
  std::vector<bool> check;
  // Arrow length per mm of error; 0: chosen from the data. Set both pictures of a before /
  // after pair the same to compare them by eye, or each its own to see the remaining pattern.
  double magnification = 0.0;
  int size_px = 900;
};
Status SaveFieldArrowsPng(const FieldArrows& spec, const std::string& path);

// Distinct colours for series i = 0, 1, ...
int PlotColor(int i);

}  // namespace insitu::job
