// The scan head's coaxial camera looking at marks the simulated laser made,
// measured with the hatch measurement of the vision module: the line spacing
// and width it reads are the ones the list asked for and the craters have, and
// the image is sharpest where the surface is in focus.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "insitu/sim/world.h"
#include "insitu/vision/mark_inspection.h"

namespace insitu {
namespace {

sim::WorldOptions Plate() {
  sim::WorldOptions w;
  w.part.kind = "plane";  // 2 mm plate on the stage, albedo 0.45
  return w;
}

// Parallel lines along x, `spacing_mm` apart, centred on (x0, y0), marked in
// focus at z.
std::vector<sim::ListMove> Hatch(double x0, double y0, double z, double spacing_mm, int lines,
                                 double length_mm) {
  std::vector<sim::ListMove> moves;
  for (int i = 0; i < lines; ++i) {
    const double y = y0 + (i - 0.5 * (lines - 1)) * spacing_mm;
    moves.push_back({sim::ListMove::Kind::kJump, {x0 - 0.5 * length_mm, y, z}});
    moves.push_back({sim::ListMove::Kind::kMark, {x0 + 0.5 * length_mm, y, z}});
  }
  return moves;
}

sim::MarkingParams Params() {
  sim::MarkingParams p;
  p.laser_on_delay_us = 100;
  p.laser_off_delay_us = 200;
  p.jump_delay_us = 300;
  p.mark_delay_us = 250;
  return p;
}

vision::ImageView View(const Frame& f) {
  return {f.bytes.data(), f.width, f.height, static_cast<size_t>(f.width), 8};
}

double Spacing(double spacing_mm, double* width_um, double* std_um) {
  sim::SimWorld world(Plate());
  const double z = 2.0;  // the plate's top
  EXPECT_TRUE(world.ExecuteMarkingList(Hatch(0.0, 0.0, z, spacing_mm, 25, 1.5), Params()).ok());
  EXPECT_TRUE(world.MoveHead({0.0, 0.0, z}).ok());
  auto frame = world.GrabCoaxial(2000.0);
  EXPECT_TRUE(frame.ok());
  vision::HatchMeasureOptions o;
  o.pixel_um = 5.0;             // the coaxial camera's nominal scale
  o.camera_rotation_deg = 0.0;  // nominal mounting; the simulated sensor is turned 0.4 deg
  o.spacing_um = spacing_mm * 1e3;
  o.centre_px = {511.5, 511.5};
  o.half_length_um = 500.0;
  o.half_width_um = 10.0 * spacing_mm * 1e3;
  auto m = vision::MeasureHatch(View(*frame), o);
  EXPECT_TRUE(m.ok()) << m.status().ToString();
  if (!m.ok()) return 0.0;
  *width_um = m->width_um;
  *std_um = m->spacing_std_um;
  std::printf(
      "spacing %.0f um: measured %.2f +- %.2f um over %d lines, width "
      "%.1f um, contrast %.2f\n",
      spacing_mm * 1e3, m->spacing_um, m->spacing_std_um, m->lines, m->width_um, m->contrast);
  return m->spacing_um;
}

TEST(Coaxial, HatchSpacingAsMarked) {
  // The simulated laser puts lines where the list says (the plate is flat, the
  // head's correction is its design), so the spacing in the image is the list's
  // to within the image scale's error: the sensor's 0.4 deg turn shortens it by
  // 2e-5, and the centre estimate of each line is good to ~0.1 px (0.5 um); the
  // mean of 20 gaps then to ~0.2 um. 1 um bounds it.
  double width = 0.0, sd = 0.0;
  EXPECT_NEAR(Spacing(0.040, &width, &sd), 40.0, 1.0);
  EXPECT_LT(sd, 2.0);
  EXPECT_NEAR(Spacing(0.120, &width, &sd), 120.0, 1.0);
  // At 120 um the lines stand apart: each is the crater's diameter wide at half
  // depth, less than the full crater (59 um at half power in focus) and more
  // than the beam's 1/e^2 diameter (40 um): the groove is a sum of paraboloids.
  EXPECT_GT(width, 30.0);
  EXPECT_LT(width, 60.0);
}

TEST(Coaxial, SharpestWhereTheSurfaceIsInFocus) {
  sim::SimWorld world(Plate());
  ASSERT_TRUE(world.ExecuteMarkingList(Hatch(0.0, 0.0, 2.0, 0.04, 25, 1.5), Params()).ok());
  std::vector<double> zs, sharp;
  for (double z = 1.0; z <= 3.01; z += 0.2) {
    ASSERT_TRUE(world.MoveHead({0.0, 0.0, z}).ok());
    auto frame = world.GrabCoaxial(2000.0);
    ASSERT_TRUE(frame.ok());
    zs.push_back(z);
    sharp.push_back(vision::Sharpness(View(*frame), {511.5, 511.5}, 100));
  }
  auto best = vision::BestFocus(zs, sharp);
  ASSERT_TRUE(best.ok()) << best.status().ToString();
  // The plate's top is at z = 2 mm. The focus curve is ~1 mm wide (NA 0.027, 40
  // um lines) and sampled every 0.2 mm with noise; its vertex is good to a few
  // hundredths of a mm.
  EXPECT_NEAR(*best, 2.0, 0.05);
  std::printf("best focus %.3f mm (surface at 2.000)\n", *best);
}

}  // namespace
}  // namespace insitu
