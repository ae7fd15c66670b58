#include "insitu/sim/scene.h"

#include <gtest/gtest.h>

namespace insitu::sim {
namespace {

const Eigen::Vector3d kDown(0, 0, -1);

TEST(Scene, VerticalRaysFindEachStepOfTheGauge) {
  PartOptions part;  // step gauge 3/5/10/15 mm, 5 mm steps from x = -10
  StageOptions stage;
  Scene scene(part, stage);
  const double xs[] = {-7.5, -2.5, 2.5, 7.5};
  const double hs[] = {3, 5, 10, 15};
  for (int i = 0; i < 4; ++i) {
    Hit hit;
    ASSERT_TRUE(scene.Intersect({xs[i], 10.0, 100.0}, kDown, 1000.0, &hit));
    EXPECT_NEAR(hit.point_in_world.z(), hs[i], 1e-5);
    EXPECT_TRUE(hit.on_part);
    EXPECT_NEAR(hit.normal.z(), 1.0, 1e-6);
  }
  Hit plate;
  ASSERT_TRUE(scene.Intersect({30.0, 0.0, 100.0}, kDown, 1000.0, &plate));
  EXPECT_FALSE(plate.on_part);
  EXPECT_NEAR(plate.point_in_world.z(), 0.0, 1e-12);
}

TEST(Scene, StageMovesThePartWithIt) {
  Scene scene(PartOptions{}, StageOptions{});
  scene.set_stage_z(-5.0);
  Hit hit;
  ASSERT_TRUE(scene.Intersect({7.5, 0.0, 100.0}, kDown, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.z(), 10.0, 1e-5);
}

// A slanted ray toward the tall step's riser hits the wall, with a horizontal normal.
TEST(Scene, SlantedRayHitsARiser) {
  Scene scene(PartOptions{}, StageOptions{});
  const Eigen::Vector3d dir = Eigen::Vector3d(1.0, 0.0, -1.0).normalized();
  Hit hit;
  // Aimed at x = 5 (riser between the 10 and 15 mm steps) at z = 12.
  ASSERT_TRUE(scene.Intersect({5.0 - 50.0, 0.0, 12.0 + 50.0}, dir, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.x(), 5.0, 1e-4);
  EXPECT_NEAR(hit.point_in_world.z(), 12.0, 1e-4);
  EXPECT_NEAR(hit.normal.x(), -1.0, 1e-6);
}

// The camera side (-x) sees the plate in front of the gauge; behind the 15 mm step (+x side)
// the plate is hidden from a camera up and to the -x side.
TEST(Scene, TallStepHidesThePlateBehindIt) {
  Scene scene(PartOptions{}, StageOptions{});
  const Eigen::Vector3d camera(-180.0, 0.0, 300.0);
  EXPECT_FALSE(scene.Blocked({-12.0, 0.0, 0.0}, camera));
  EXPECT_TRUE(scene.Blocked({12.0, 0.0, 0.0}, camera));
  EXPECT_FALSE(scene.Blocked({7.5, 0.0, 15.0}, camera));  // the top itself is visible
}

TEST(Scene, InsertHasAHoleAndARakeBand) {
  PartOptions part;
  part.kind = "insert";
  Scene scene(part, StageOptions{});
  Hit hit;
  ASSERT_TRUE(scene.Intersect({0.0, 0.0, 100.0}, kDown, 1000.0, &hit));
  EXPECT_FALSE(hit.on_part);  // straight down the hole onto the plate
  // Just inside the bottom edge (edge facing -y at y = -inradius): top at full thickness,
  // sloping down inward by the rake angle.
  const double inradius = part.insert_edge_mm / (2.0 * std::sqrt(3.0));
  ASSERT_TRUE(scene.Intersect({0.0, -inradius + 0.01, 100.0}, kDown, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.z(), part.insert_thickness_mm, 0.01);
  ASSERT_TRUE(scene.Intersect({0.0, -inradius + 1.0, 100.0}, kDown, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.z(),
              part.insert_thickness_mm - std::tan(part.insert_rake_deg * M_PI / 180.0), 0.01);
}

TEST(Scene, ArcCrownHasItsNominalHeights) {
  PartOptions part;
  part.kind = "arc";
  Scene scene(part, StageOptions{});
  EXPECT_NEAR(scene.TrueHeightAt(0.0, 0.0), part.arc_height_mm, 1e-9);
  EXPECT_NEAR(scene.TrueHeightAt(part.arc_width_mm / 2 - 1e-9, 0.0), part.arc_edge_height_mm,
              1e-6);
}

}  // namespace
}  // namespace insitu::sim
