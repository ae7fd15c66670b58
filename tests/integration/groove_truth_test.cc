// Grooves the simulated head cut through a panel's maskant, read by the simulated line
// profiler and fitted by the groove template (seed 002 section 2.1), against the simulator's
// truth: the centre, width and depth of the true cross-section along each profile's line.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "insitu/inspect/groove.h"
#include "insitu/sim/world.h"

namespace insitu {
namespace {

constexpr double kTop = 2.31;

struct Truth {
  double centre_mm, width_mm, depth_mm, top_width_mm;
};

// The true cross-section along the sensor's line: depth below the film sampled every 2 um
// in sensor x; the groove's centre midway between its half-depth points, its width twice
// their distance (the template's w: the opening of a V), its depth the deepest point.
Truth TrueSection(const sim::SimWorld& w, double x_from, double x_to) {
  const Eigen::Isometry3d s = w.TrueSensorInWorld();
  std::vector<double> xs, ds;
  for (double x = x_from; x <= x_to; x += 0.002) {
    const Eigen::Vector3d p = s * Eigen::Vector3d(x, 0, 0);
    xs.push_back(x);
    ds.push_back(w.AblatedDepthMm(p.x(), p.y()));
  }
  const size_t k = std::max_element(ds.begin(), ds.end()) - ds.begin();
  const double half = 0.5 * ds[k];
  size_t l = k, r = k;
  while (l > 0 && ds[l] > half) --l;
  while (r + 1 < ds.size() && ds[r] > half) ++r;
  const auto cross = [&](size_t a, size_t b) {
    return xs[a] + (half - ds[a]) / (ds[b] - ds[a]) * (xs[b] - xs[a]);
  };
  const double xl = cross(l, l + 1), xr = cross(r - 1, r);
  size_t l0 = k, r0 = k;
  while (l0 > 0 && ds[l0] > 0) --l0;
  while (r0 + 1 < ds.size() && ds[r0] > 0) ++r0;
  return {0.5 * (xl + xr), 2.0 * (xr - xl), ds[k], xs[r0] - xs[l0]};
}

struct Cut {
  const char* name;
  double speed_mm_per_s;
  int passes;
  double x_mm = 5.0;       // where along the panel's x (the bow's slope varies along it)
  double bow_mm = 0.0;     // the clamping bend
};

struct Errors {
  double centre_um, width_um, depth_pct;
  int fitted, profiles;
};

// Cuts a groove along y, focused 10 mm above the film (a 0.22 mm beam radius there), reads 60
// profiles across it 0.33 mm apart, alpha chosen from the first ten (seed 002 Fig. 4), and
// returns the mean absolute errors of the fitted centre, width and depth against the truth.
Errors Measure(const Cut& cut) {
  sim::WorldOptions o;
  o.part.kind = "panel";
  o.part.panel_size_mm = {60.0, 40.0};
  o.part.panel_bow_mm = cut.bow_mm;
  o.part.ablation_threshold_j_per_cm2 = 3.0;  // aluminium under the film
  o.gantry.present = true;
  o.profiler.present = true;
  sim::SimWorld w(o);
  const double top = kTop + cut.bow_mm * 0.5 * (1.0 + std::cos(M_PI * cut.x_mm / 30.0));
  sim::MarkingParams p;
  p.power_fraction = 1.0;
  p.mark_speed_mm_per_s = cut.speed_mm_per_s;
  std::vector<sim::ListMove> moves;
  for (int k = 0; k < cut.passes; ++k) {
    moves.push_back({sim::ListMove::Kind::kJump, {cut.x_mm, -15.0, top + 10.0}});
    moves.push_back({sim::ListMove::Kind::kMark, {cut.x_mm, 15.0, top + 10.0}});
  }
  EXPECT_TRUE(w.ExecuteMarkingList(moves, p).ok());
  std::vector<inspect::Profile> profiles;
  std::vector<Truth> truth;
  for (int k = 0; k < 60; ++k) {
    EXPECT_TRUE(w.MoveGantry({0.0, 40.2 - 10.0 + 0.33 * k, top + 139.6, 0.0}).ok());
    auto shot = w.GrabProfile();
    EXPECT_TRUE(shot.ok());
    if (!shot.ok()) return {};
    inspect::Profile pr;
    pr.x_start_mm = -0.5 * (o.profiler.points - 1) * o.profiler.x_spacing_mm;
    pr.dx_mm = o.profiler.x_spacing_mm;
    pr.z_mm = shot->z_mm;
    profiles.push_back(pr);
    truth.push_back(TrueSection(w, cut.x_mm - 1.5, cut.x_mm + 1.5));
  }
  inspect::GrooveOptions go;
  go.z_resolution_mm = o.profiler.z_resolution_mm;
  go.z_min_mm = o.profiler.z_min_mm;
  go.z_max_mm = o.profiler.z_max_mm;
  go.expected_x_mm = truth[0].centre_mm;  // the scan plan's line, to a few um
  go.window_mm = 1.0;
  auto alpha = inspect::ChooseAlpha({profiles.begin(), profiles.begin() + 10}, go);
  EXPECT_TRUE(alpha.ok()) << alpha.status().ToString();
  if (!alpha.ok()) return {};
  go.alpha_per_mm = alpha->alpha_per_mm;
  Errors e{0, 0, 0, 0, static_cast<int>(profiles.size())};
  for (size_t k = 0; k < profiles.size(); ++k) {
    const inspect::Groove g = inspect::FitGroove(profiles[k], go);
    EXPECT_TRUE(g.ok) << cut.name << " profile " << k << ": " << g.why;
    if (!g.ok) continue;
    const Truth& t = truth[k];
    e.centre_um += 1e3 * std::abs(g.x_mm - t.centre_mm);
    e.width_um += 1e3 * std::abs(g.width_mm - t.width_mm);
    e.depth_pct += 100 * std::abs(g.depth_mm - t.depth_mm) / t.depth_mm;
    ++e.fitted;
  }
  if (e.fitted > 0) {
    e.centre_um /= e.fitted;
    e.width_um /= e.fitted;
    e.depth_pct /= e.fitted;
  }
  std::printf("%s (alpha %g /mm, truth: width %.1f um, depth %.1f um, opening %.1f um): mean "
              "absolute errors centre %.2f um, width %.2f um, depth %.2f %%\n",
              cut.name, go.alpha_per_mm, 1e3 * truth[0].width_mm, 1e3 * truth[0].depth_mm,
              1e3 * truth[0].top_width_mm, e.centre_um, e.width_um, e.depth_pct);
  return e;
}

// The bars: centre and width within 4 um mean absolute error, depth within 1 % (seed
// 002 reached 8.1 +- 7.2 um of fit and 2.59 % in depth). What the noise allows: 1.5 um of
// speckle per point; each half-depth point from ~4 flank points at a slope of ~3, ~0.4 um; the
// depth from ~5 bottom points and the surface line, ~1 um (0.3 %).
TEST(GrooveTruth, CentreWidthAndDepthAgainstTheTruth) {
  for (const Cut& cut : {Cut{"one pass, short of the metal", 260.0, 1},
                         Cut{"two passes, through to the metal", 300.0, 2},
                         Cut{"one pass on a panel bowed 0.5 mm, where it slopes", 260.0, 1, -15.0,
                             0.5}}) {
    const Errors e = Measure(cut);
    EXPECT_EQ(e.fitted, e.profiles) << cut.name;
    EXPECT_LT(e.centre_um, 4.0) << cut.name;
    EXPECT_LT(e.width_um, 4.0) << cut.name;
    EXPECT_LT(e.depth_pct, 1.0) << cut.name;
  }
}

}  // namespace
}  // namespace insitu
