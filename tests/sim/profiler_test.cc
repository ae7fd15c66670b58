// The simulated line profiler on its gantry, over a clamped panel whose maskant the marking
// laser grooved: the range it reads against the surface it stands over, the groove's shape as
// the ablation law cuts it (through the film, floored by the metal), points the fan cannot
// reach left invalid, and the gantry's travel and encoder.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "insitu/sim/world.h"

namespace insitu::sim {
namespace {

constexpr double kTop = 2.31;  // the film's top: 2 mm of skin and 0.31 mm of maskant

WorldOptions PanelCell() {
  WorldOptions w;
  w.part.kind = "panel";
  w.part.panel_size_mm = {60.0, 40.0};
  w.part.ablation_threshold_j_per_cm2 = 3.0;  // aluminium under the film
  w.gantry.present = true;
  w.profiler.present = true;
  w.profiler.spike_rate = 0.0;  // every reading the surface's, within its noise
  return w;
}

// Two passes along y at x_mm, focused 10 mm above the film (a 0.22 mm beam radius there).
void Engrave(SimWorld* w, double x_mm) {
  MarkingParams p;
  p.power_fraction = 1.0;
  p.mark_speed_mm_per_s = 300.0;
  std::vector<ListMove> moves;
  for (int pass = 0; pass < 2; ++pass) {
    moves.push_back({ListMove::Kind::kJump, {x_mm, -15.0, kTop + 10.0}});
    moves.push_back({ListMove::Kind::kMark, {x_mm, 15.0, kTop + 10.0}});
  }
  ASSERT_TRUE(w->ExecuteMarkingList(moves, p).ok());
}

struct Point {
  Eigen::Vector3d world;  // on the sensor's line, at its reading
  double truth_z;         // the true surface along the sensor's z there, sensor frame
  float reading;
};

// Each point of one profile beside where the true surface is along the sensor's z.
std::vector<Point> Shoot(SimWorld* w) {
  auto shot = w->GrabProfile();
  EXPECT_TRUE(shot.ok()) << shot.status().ToString();
  const auto& o = w->options().profiler;
  const Eigen::Isometry3d s = w->TrueSensorInWorld();
  const Eigen::Vector3d axis = s.linear().col(2);
  std::vector<Point> out;
  for (int i = 0; i < o.points; ++i) {
    const Eigen::Vector3d base = s * Eigen::Vector3d(-0.5 * (o.points - 1) * o.x_spacing_mm +
                                                         i * o.x_spacing_mm, 0.0, 0.0);
    double z = 0.0;  // fixed point on the all-but-vertical line
    for (int it = 0; it < 30; ++it) {
      const Eigen::Vector3d p = base + z * axis;
      z -= (p.z() - w->TrueSurfaceZ(p.x(), p.y())) / axis.z();
    }
    out.push_back({base + z * axis, z, shot.ok() ? shot->z_mm[i] : NAN});
  }
  return out;
}

TEST(Profiler, ReadsTheSurfaceWithinItsNoise) {
  SimWorld w(PanelCell());
  Engrave(&w, 5.0);
  ASSERT_TRUE(w.MoveGantry({0.0, 40.2, kTop + 139.6, 0.0}).ok());
  const auto points = Shoot(&w);
  // Speckle 1.5 um and a 0.5 um count: every valid reading within 6 sigma of the truth,
  // on the film, in the groove and on the plate beside the panel alike.
  int valid = 0, groove = 0, floor = 0;
  double deepest = 0.0;
  for (const Point& p : points) {
    if (std::isnan(p.reading)) continue;
    ++valid;
    EXPECT_NEAR(p.reading, p.truth_z, 6 * 1.5e-3 + 0.25e-3) << "at world x " << p.world.x();
    const double depth = w.AblatedDepthMm(p.world.x(), p.world.y());
    if (depth > 0) ++groove;
    if (depth > 0.309) ++floor;
    deepest = std::max(deepest, depth);
  }
  // The film is cut through: the metal floors the groove at the film's 0.31 mm.
  EXPECT_NEAR(deepest, 0.31, 1e-6);
  EXPECT_GE(floor, 4);
  // 2 R = 2 w sqrt(ln(F0 / F_th) / 2) with w = 0.22 mm, F0 = 1.30 J/cm^2, F_th 0.15: 0.46 mm,
  // 18 points at 25 um (the line all but square to the groove).
  EXPECT_GE(groove, 15);
  EXPECT_LE(groove, 20);
  // The line is 80 mm and the panel 60: both of its walls throw the fan's shadow on the plate
  // beside them, 2.31 mm x 30 / 140 = 0.5 mm wide, ~20 points each.
  EXPECT_GT(valid, 3200 - 2 * 25);
  EXPECT_LT(valid, 3200 - 2 * 15);
}

TEST(Profiler, TheWallsHideThePlateFromTheFanAndTheCamera) {
  SimWorld w(PanelCell());
  ASSERT_TRUE(w.MoveGantry({0.0, 40.2, kTop + 139.6, 0.0}).ok());
  const auto points = Shoot(&w);
  // The fan's source, 140 mm over the line's middle, and the wall's top edge hide the plate
  // past each wall out to where the ray over the edge lands: top x d / (source height - top),
  // d the source's distance from the wall (~0.5 mm). The camera, 140 mm off at 25 deg toward
  // -y, sees past the wall no farther (lower, it is hidden out to ~0.57 mm): the invalid band
  // is the wider of the two. A point's width of slack either side.
  const double th = 25.0 * M_PI / 180.0;
  const Eigen::Vector3d fan = w.TrueSensorInWorld() * Eigen::Vector3d(0, 0, 140.0);
  const Eigen::Vector3d camera =
      w.TrueSensorInWorld() * Eigen::Vector3d(0, -140.0 * std::sin(th), 140.0 * std::cos(th));
  for (const Point& p : points) {
    const double wall = p.world.x() > 0 ? 30.0 : -30.0;
    const double beyond = std::abs(p.world.x()) - 30.0;  // past the wall, on the plate
    const double shadow = std::max(kTop * std::abs(wall - fan.x()) / (fan.z() - kTop),
                                   kTop * std::abs(wall - camera.x()) / (camera.z() - kTop));
    if (beyond > 0.03 && beyond < shadow - 0.03) {
      EXPECT_TRUE(std::isnan(p.reading)) << p.world.x();
    } else if (beyond > shadow + 0.03) {
      EXPECT_FALSE(std::isnan(p.reading)) << p.world.x();
    }
  }
}

TEST(Profiler, RangeAndTravel) {
  SimWorld w(PanelCell());
  // Raised 12 mm: the film lies beyond the -10 mm end of the range.
  ASSERT_TRUE(w.MoveGantry({0.0, 40.2, kTop + 139.6 + 12.0, 0.0}).ok());
  auto shot = w.GrabProfile();
  ASSERT_TRUE(shot.ok());
  for (float z : shot->z_mm) EXPECT_TRUE(std::isnan(z));
  EXPECT_EQ(shot->encoder, 40200);  // 1000 counts per mm
  const Status s = w.MoveGantry({0.0, 400.0, 150.0, 0.0});
  EXPECT_EQ(s.code(), StatusCode::kOutOfRange);
  EXPECT_NE(s.message().find("gantry y"), std::string::npos) << s.message();
  WorldOptions none;
  SimWorld bare(none);
  EXPECT_EQ(bare.GrabProfile().status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(bare.MoveGantry({0, 0, 0, 0}).code(), StatusCode::kFailedPrecondition);
}

TEST(Profiler, TurnedByCTheLineCrossesAGrooveAlongX) {
  SimWorld w(PanelCell());
  // A groove along x at y = 3 (the marks run along the head's x axis).
  MarkingParams p;
  p.power_fraction = 1.0;
  p.mark_speed_mm_per_s = 300.0;
  ASSERT_TRUE(w.ExecuteMarkingList({{ListMove::Kind::kJump, {-20.0, 3.0, kTop + 10.0}},
                                    {ListMove::Kind::kMark, {20.0, 3.0, kTop + 10.0}}},
                                   p)
                  .ok());
  // C at 90 deg turns the sensor's x onto the world's y; the mount's -40.2 mm offset in y
  // comes round to +40.2 in x.
  ASSERT_TRUE(w.MoveGantry({-40.2, 0.0, kTop + 139.6, 90.0}).ok());
  const auto points = Shoot(&w);
  int groove = 0;
  for (const Point& q : points) {
    if (std::isnan(q.reading)) continue;
    EXPECT_NEAR(q.reading, q.truth_z, 6 * 1.5e-3 + 0.25e-3);
    groove += w.AblatedDepthMm(q.world.x(), q.world.y()) > 0.1 ? 1 : 0;
  }
  EXPECT_GE(groove, 8);
}

// A film as thick as the seed's measured grooves are deep (0.3124 mm, no float), over metal the
// pulses do cut (threshold 0.5 J/cm^2, under the 1.30 at the film): two passes go through the
// film and into the metal, where the ablation law goes on.
TEST(Profiler, TheFilmIsCutThroughToAMetalThePulsesAblate) {
  WorldOptions o = PanelCell();
  o.part.maskant_thickness_mm = 0.3124;
  o.part.ablation_threshold_j_per_cm2 = 0.5;
  SimWorld w(o);
  Engrave(&w, 5.0);
  double deepest = 0.0;
  for (double x = 4.5; x <= 5.5; x += 0.002) deepest = std::max(deepest, w.AblatedDepthMm(x, 0.0));
  EXPECT_GT(deepest, 0.3124 + 0.001);
}

}  // namespace
}  // namespace insitu::sim
