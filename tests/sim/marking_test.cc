// The simulated marking laser: craters where the beam meets the surface, their size from the
// pulse fluence and the beam radius there (so marks widen out of focus), the pulse spacing
// from speed and rate, and the mirrors' lag that the RTC delays exist to compensate.
#include <atomic>
#include <cmath>

#include <gtest/gtest.h>

#include "insitu/sim/world.h"

namespace insitu::sim {
namespace {

WorldOptions Plate() {
  WorldOptions w;
  w.part.kind = "none";  // the bare stage plate at z = 0
  return w;
}

// Liu's relation for the default marking beam (30 W, 40 um waist diameter, M^2 1.3, 1064 nm)
// at half power and 30 kHz: E = 0.5 mJ; F0 = 2E / (pi w^2); D^2 = 2 w^2 ln(F0 / F_th).
double ExpectedDiameter(const WorldOptions& o, double defocus_mm, double threshold) {
  const auto& b = o.scan_head.marking;
  const double w0 = 0.5 * b.waist_diameter_mm;
  const double zr = M_PI * w0 * w0 / (b.m2 * b.wavelength_nm * 1e-6);
  const double w = w0 * std::sqrt(1.0 + std::pow(defocus_mm / zr, 2));
  const double f0 = 2.0 * (b.power_mw * 1e-3 * 0.5 / 30e3) / (M_PI * std::pow(w * 0.1, 2));
  return w * std::sqrt(2.0 * std::log(f0 / threshold));
}

std::vector<ListMove> Line(double z_focus) {
  return {{ListMove::Kind::kJump, {-2.0, 5.0, z_focus}}, {ListMove::Kind::kMark, {3.0, 5.0, z_focus}}};
}

// An abort flag set while the list runs (here by the progress callback, a third of the way
// in) stops the laser on the tick the head sees it: no pulse after it, and the list's rest is
// not run.
TEST(Marking, AnAbortedListStopsTheLaserOnTheTickItIsSeen) {
  SimWorld w(Plate());
  MarkingParams p;
  p.jump_delay_us = 2000;
  std::vector<ListMove> moves;
  for (int k = 0; k < 20; ++k) {  // 20 lines of 10 mm at 1000 mm/s: 0.2 s of marking
    moves.push_back({ListMove::Kind::kJump, {-5.0, -5.0 + 0.5 * k, 0.0}});
    moves.push_back({ListMove::Kind::kMark, {5.0, -5.0 + 0.5 * k, 0.0}});
  }
  std::atomic<bool> abort{false};
  double asked_at = -1.0;
  const Status s = w.ExecuteMarkingList(moves, p, &abort, [&](double fraction) {
    if (fraction >= 0.3 && !abort) {
      abort = true;
      asked_at = fraction;
    }
  });
  EXPECT_EQ(s.code(), StatusCode::kCancelled);
  const ListAbortTruth& a = w.last_list_abort();
  ASSERT_TRUE(a.aborted);
  ASSERT_GT(asked_at, 0.0);
  const double tick_s = Plate().scan_head.clock_us * 1e-6;
  const double list_s = a.list_end_s - a.list_start_s;
  // Seen on the very next tick after the flag was set (the callback runs before the tick's
  // check on the following iteration).
  EXPECT_NEAR(a.seen_at_s - a.list_start_s, asked_at * list_s, 1.5 * tick_s);
  double last = 0.0;
  for (const MarkPulse& q : w.mark_pulses()) last = std::max(last, q.t_s);
  EXPECT_LE(last, a.seen_at_s + 1e-12);
  EXPECT_GT(last, a.seen_at_s - 0.01);  // the laser was on until then (it was marking)
  EXPECT_NEAR(w.now_s(), a.seen_at_s, 1e-12);  // the clock stops with the list
}

TEST(Marking, CratersInFocusAlongTheLine) {
  const WorldOptions o = Plate();
  SimWorld w(o);
  MarkingParams p;  // 1000 mm/s, 30 kHz: pulses 33 um apart
  p.jump_delay_us = 2000;  // let the mirrors arrive before marking
  p.laser_off_delay_us = 1000;
  ASSERT_TRUE(w.ExecuteMarkingList(Line(0.0), p).ok());
  const auto& pulses = w.mark_pulses();
  // 5 mm at 1000 mm/s = 5 ms, plus the off delay's 1 ms at the end point: >= 150 pulses.
  ASSERT_GE(pulses.size(), 150u);
  const double expected = ExpectedDiameter(o, 0.0, o.stage.plate_ablation_threshold_j_per_cm2);
  double y_max_err = 0;
  for (const MarkPulse& q : pulses) {
    // In focus on the plate: |defocus| < 0.01 mm (the head's design correction vs the as-built
    // optics), so the crater is the in-focus one to 0.1 %.
    EXPECT_LT(std::abs(q.defocus_mm), 0.01);
    EXPECT_NEAR(q.diameter_mm, expected, 1e-3 * expected);
    EXPECT_GT(q.point_in_world.x(), -2.05);
    EXPECT_LT(q.point_in_world.x(), 3.05);
    y_max_err = std::max(y_max_err, std::abs(q.point_in_world.y() - 5.0));
  }
  // The head's correction table is its design; in the default world the as-built optics are
  // the design and the mirrors have no zero error, so the spot lands on the command.
  EXPECT_LT(y_max_err, 1e-3);
  std::printf("in focus: %zu pulses, crater %.1f um, |y - 5| <= %.3f mm\n", pulses.size(),
              expected * 1e3, y_max_err);
}

// 1.5 mm above the plate the beam radius grows by sqrt(1 + (1.5 / z_R)^2) (z_R ~0.9 mm) and
// the crater with it, while the fluence is still far above threshold.
TEST(Marking, MarksWidenOutOfFocus) {
  const WorldOptions o = Plate();
  SimWorld w(o);
  MarkingParams p;
  p.jump_delay_us = 2000;
  ASSERT_TRUE(w.ExecuteMarkingList(Line(1.5), p).ok());
  ASSERT_FALSE(w.mark_pulses().empty());
  const MarkPulse& q = w.mark_pulses()[w.mark_pulses().size() / 2];
  EXPECT_NEAR(q.defocus_mm, 1.5, 0.01);
  const double in_focus = ExpectedDiameter(o, 0.0, o.stage.plate_ablation_threshold_j_per_cm2);
  const double out = ExpectedDiameter(o, q.defocus_mm, o.stage.plate_ablation_threshold_j_per_cm2);
  EXPECT_NEAR(q.diameter_mm, out, 1e-3 * out);
  EXPECT_GT(q.diameter_mm, 1.3 * in_focus);
}

// Without a laser-off delay the laser stops when the command reaches the end, while the
// mirrors still lag by speed x lag = 1000 mm/s x 0.16 ms = 0.16 mm: the mark ends short. A
// laser-off delay of a few lags lets the mirrors arrive.
TEST(Marking, LaserOffDelayCompensatesTheMirrorLag) {
  const WorldOptions o = Plate();
  auto last_x = [&](double off_delay_us) {
    SimWorld w(o);
    MarkingParams p;
    p.jump_delay_us = 2000;
    p.laser_off_delay_us = off_delay_us;
    EXPECT_TRUE(w.ExecuteMarkingList(Line(0.0), p).ok());
    double x = -1e9;
    for (const MarkPulse& q : w.mark_pulses()) x = std::max(x, q.point_in_world.x());
    return x;
  };
  const double short_end = last_x(0.0), full_end = last_x(1000.0);
  std::printf("mark ends at x = %.3f mm without, %.3f mm with the off delay (command: 3)\n",
              short_end, full_end);
  EXPECT_NEAR(3.0 - short_end, 0.16, 0.05);  // lag, +- a pulse spacing and the spot error
  EXPECT_NEAR(full_end, 3.0, 0.05);
}

TEST(Marking, BadListsAreRefused) {
  SimWorld w(Plate());
  MarkingParams p;
  EXPECT_EQ(w.ExecuteMarkingList({{ListMove::Kind::kMark, {100.0, 0.0, 0.0}}}, p).code(),
            StatusCode::kOutOfRange);
  p.pulse_frequency_khz = 0;
  EXPECT_EQ(w.ExecuteMarkingList(Line(0.0), p).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(w.mark_pulses().empty());
}

}  // namespace
}  // namespace insitu::sim
