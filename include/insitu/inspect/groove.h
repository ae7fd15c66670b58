// One profile of a line profiler across an engraved groove, and the groove found in it (seed 002,
// section 2.1): outliers removed, the profile levelled on its surface (eq. 12-13), the tanh
// template (eq. 11)
//   z = z0 + 0.5 d (tanh(alpha (x - x0 - w / 4)) - tanh(alpha (x - x0 + w / 4)))
// fitted by Levenberg-Marquardt (eq. 14-19; Ceres's TinySolver, analytic Jacobian), and the
// centre rotated back to the profile's frame. The template's edges (its half-depth points) lie
// at x0 -+ w / 4, which is where a V-groove of top width w has half its depth: w is the groove's
// width at the surface. With alpha finite the two edges overlap and the template's deepest point
// is d tanh(alpha w / 4) below its surface: that is the depth reported.
//
// alpha is the template's edge sharpness (1/mm). Seed 002 picks it by eye (20 /mm, Fig. 4);
// ChooseAlpha picks it from data: the value whose template fits a sample of profiles best.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::inspect {

// One profile: z at x = x_start_mm + i dx_mm, i = 0 .. z_mm.size() - 1 (the sensor's X over its
// line, Z its range); NaN where the sensor returned its invalid value (occlusion, no signal).
struct Profile {
  double x_start_mm = 0.0;
  double dx_mm = 0.01;
  std::vector<float> z_mm;
  int64_t stamp = 0;  // position or encoder count of the profile (the scan's direction)
};

struct GrooveOptions {
  // The groove's expected width (seed 002's l): the levelling cuts +-this about the deepest point
  // before fitting the surface line, and it starts the fit.
  double expected_width_mm = 0.5;
  // Points used: those within +-window_mm of the deepest point (seed 002's t points); 0: all.
  double window_mm = 1.0;
  double alpha_per_mm = 20.0;  // the template's edge sharpness
  // A point is an outlier when it departs from the median of its neighbours (5 points) by more
  // than this many robust standard deviations (1.4826 MAD of those departures).
  double outlier_sigmas = 6.0;
  int max_iterations = 100;
  // The sensor's range resolution: the least scatter a deviation is measured against (a flat
  // run of equal readings has none, and one count more is not an outlier).
  double z_resolution_mm = 0.001;
  // The sensor's measuring range: a reading outside it is the sensor's invalid value or a
  // dropout (seed 002: "returns an abnormal value"), not a point.
  double z_min_mm = -std::numeric_limits<double>::infinity();
  double z_max_mm = std::numeric_limits<double>::infinity();
  // Where along the profile the groove is expected (the scan plan's design line): the profile
  // is cut to +-window_mm about it before anything else (seed 002 keeps the middle t points),
  // so a neighbouring groove on a long profile is not taken for it. NaN: the whole profile.
  double expected_x_mm = std::numeric_limits<double>::quiet_NaN();
  Status Validate() const;
};

struct Groove {
  bool ok = false;
  std::string why;        // when not ok: what was wrong with the profile
  double x_mm = 0.0;      // centre, profile frame
  double z_mm = 0.0;      // surface height at the centre, profile frame
  // Measured from the groove's points, placed by the template: its deepest point below the
  // surface, and twice the distance between its half-depth points (seed 002's w: the opening
  // of a V-groove of that half-depth width). The centre is midway between those points.
  double depth_mm = 0.0;
  double width_mm = 0.0;
  double template_depth_mm = 0.0;  // the fitted template's own (eq. 11)
  double template_width_mm = 0.0;
  double tilt_rad = 0.0;  // the surface's slope in the profile (levelling)
  double rms_mm = 0.0;    // fit residual, rms over the points used
  int points = 0;         // used in the fit
  int outliers = 0;       // removed before it
  int iterations = 0;
};

// The groove in one profile. Never throws; a profile without a groove (too few valid points, no
// depth, a fit that does not converge) comes back with ok false and the reason.
Groove FitGroove(const Profile& profile, const GrooveOptions& options);

// alpha from data (Fig. 4 of seed 002, decided by the numbers): each candidate's template is
// fitted to every profile of the sample and the one with the smallest rms residual over the
// sample wins. `rms_mm[k]` receives candidate k's rms (NaN when no profile fitted).
struct AlphaChoice {
  double alpha_per_mm = 0.0;
  std::vector<double> candidates, rms_mm;
};
// Errors: invalid_argument (no candidates, bad options), failed_precondition (no profile of the
// sample holds a groove at any candidate).
Result<AlphaChoice> ChooseAlpha(const std::vector<Profile>& sample, GrooveOptions options,
                                const std::vector<double>& candidates = {5, 7, 10, 14, 20, 28, 40,
                                                                         56, 80, 113, 160});

}  // namespace insitu::inspect
