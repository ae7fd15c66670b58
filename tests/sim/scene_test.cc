#include "insitu/sim/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

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


// The reticle: a glass square of its thickness, chrome crosses where the options put them
// (turned and shifted with the part), the glass between them, and the pixel-footprint
// average equal to the chrome's share of the footprint's triangle weight.
TEST(Scene, GridPlateCarriesChromeCrosses) {
  PartOptions part;
  part.kind = "grid_plate";
  part.position_mm = {0.3, -0.2};
  part.rotation_deg = 1.0;
  ASSERT_TRUE(part.Validate().ok());
  Scene scene(part, StageOptions{});
  EXPECT_EQ(scene.grid_plate_crosses_per_side(), 6);  // (14 - 0.5) / 2 / 1 mm
  EXPECT_NEAR(scene.TrueHeightAt(0.3, -0.2), part.grid_plate_thickness_mm, 1e-12);
  EXPECT_EQ(scene.TrueHeightAt(8.0, 0.0), 0.0);  // off the 14 mm glass
  const Eigen::Vector2d c = scene.GridCrossInWorld(2, -3);
  const double t = 1.0 * M_PI / 180.0;
  EXPECT_NEAR(c.x(), 0.3 + 2.0 * std::cos(t) + 3.0 * std::sin(t), 1e-12);
  EXPECT_NEAR(c.y(), -0.2 + 2.0 * std::sin(t) - 3.0 * std::cos(t), 1e-12);
  EXPECT_EQ(scene.PartAlbedoAt(c.x(), c.y()), part.grid_plate_chrome_albedo);
  // Along the bar 0.2 mm out (inside its 0.25 mm half length), then just past its end.
  const Eigen::Vector2d along(std::cos(t), std::sin(t));
  EXPECT_EQ(scene.PartAlbedoAt(c.x() + 0.2 * along.x(), c.y() + 0.2 * along.y()),
            part.grid_plate_chrome_albedo);
  EXPECT_EQ(scene.PartAlbedoAt(c.x() + 0.26 * along.x(), c.y() + 0.26 * along.y()),
            part.grid_plate_glass_albedo);
  // Half way between crosses: glass.
  const Eigen::Vector2d mid = 0.5 * (c + scene.GridCrossInWorld(3, -2));
  EXPECT_EQ(scene.PartAlbedoAt(mid.x(), mid.y()), part.grid_plate_glass_albedo);
  // A triangle footprint of 10 um half-width centred on a bar away from the crossing: the
  // 9 um line holds 1 - (5.5 / 10)^2 of its weight.
  const Eigen::Vector2d bar = c + 0.1 * along;
  EXPECT_NEAR(scene.PartAlbedoAt(bar.x(), bar.y(), 0.010),
              0.05 + (0.55 - 0.05) * (1.0 - 0.3025), 1e-3);  // the 1 deg turn: < 1e-3
  // The ray hits the top at the reticle's thickness and reads the pattern there.
  Hit hit;
  ASSERT_TRUE(scene.Intersect({c.x(), c.y(), 100.0}, kDown, 1000.0, &hit));
  EXPECT_TRUE(hit.on_part);
  EXPECT_NEAR(hit.point_in_world.z(), part.grid_plate_thickness_mm, 1e-5);
  EXPECT_EQ(hit.albedo, part.grid_plate_chrome_albedo);
  // Bad reticles are refused by name.
  PartOptions bad = part;
  bad.grid_plate_cross_mm = 1.2;
  EXPECT_NE(bad.Validate().message().find("grid_plate_cross_mm"), std::string::npos);
  bad = part;
  bad.grid_plate_line_um = 0.0;
  EXPECT_NE(bad.Validate().message().find("grid_plate_line_um"), std::string::npos);
}

// A bowed plate (a dome of 1 mm over the 400 mm plate: PlateWarp = -bow r^2 / 200^2): slanted
// rays land on the curved top itself (to 1e-9 mm: four passes of the slope-times-inclination
// contraction), with the bow's normal.
TEST(Scene, ABowedPlateIsHitOnItsCurvedTop) {
  PartOptions none;
  none.kind = "none";
  StageOptions stage;
  stage.plate_bow_mm = 1.0;
  Scene scene(none, stage);
  EXPECT_NEAR(scene.PlateWarp(100.0, 0.0), -0.25, 1e-12);
  const Eigen::Vector3d dir = Eigen::Vector3d(0.6, 0.3, -1.0).normalized();
  Hit hit;
  ASSERT_TRUE(scene.Intersect({40.0, -70.0, 200.0}, dir, 1000.0, &hit));
  const Eigen::Vector3d& p = hit.point_in_world;
  EXPECT_NEAR(p.z(), scene.PlateWarp(p.x(), p.y()), 1e-9);
  EXPECT_NEAR(scene.TrueHeightAt(p.x(), p.y()), p.z(), 1e-9);
  const double k = -1.0 / (200.0 * 200.0);
  const Eigen::Vector3d n = Eigen::Vector3d(-2 * k * p.x(), -2 * k * p.y(), 1.0).normalized();
  EXPECT_NEAR((hit.normal - n).norm(), 0.0, 1e-12);
  // The stage carries the bow with it.
  scene.set_stage_z(-5.0);
  ASSERT_TRUE(scene.Intersect({0.0, 0.0, 100.0}, kDown, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.z(), -5.0, 1e-12);
}

// The gauge (20 x 80 mm) rests rigidly on a bowed plate: on a dome's crown at the centre
// (heights as on a flat plate), on its four corners in a dish (lifted by the curvature times
// 10^2 + 40^2 mm^2), and off centre tilted by the slope under its centre.
TEST(Scene, APartRestsRigidlyOnABowedPlate) {
  const double xs[] = {-7.5, -2.5, 2.5, 7.5};
  const double hs[] = {3, 5, 10, 15};
  for (double bow : {1.0, -1.0}) {
    StageOptions stage;
    stage.plate_bow_mm = bow;
    Scene scene(PartOptions{}, stage);
    const double lift = bow > 0 ? 0.0 : 1700.0 / 40000.0;
    for (int i = 0; i < 4; ++i) {
      for (double y : {-35.0, 0.0, 35.0}) {
        Hit hit;
        ASSERT_TRUE(scene.Intersect({xs[i], y, 100.0}, kDown, 1000.0, &hit));
        EXPECT_TRUE(hit.on_part);
        EXPECT_NEAR(hit.point_in_world.z(), hs[i] + lift, 1e-5) << "bow " << bow;
        EXPECT_NEAR(scene.TrueHeightAt(xs[i], y), hs[i] + lift, 1e-5) << "bow " << bow;
      }
    }
  }
  StageOptions stage;
  stage.plate_bow_mm = 1.0;
  PartOptions part;
  part.position_mm = {50.0, 0.0};
  Scene scene(part, stage);
  // Under the centre the dome stands at -1 50^2 / 200^2 = -0.0625 and falls by 2.5e-3 per mm
  // in x: the 15 mm step's top, 7.5 mm to +x of the centre, stands that much lower (the tilt
  // moves the top sideways by 15 mm x 2.5e-3 too: 1e-4 of slope's worth of height).
  Hit hit;
  ASSERT_TRUE(scene.Intersect({57.5, 0.0, 100.0}, kDown, 1000.0, &hit));
  EXPECT_NEAR(hit.point_in_world.z(), 15.0 - 0.0625 - 7.5 * 2.5e-3, 2e-4);
  EXPECT_NEAR(hit.normal.x(), 2.5e-3, 1e-6);
  // The height by world xy is the top's on the same vertical (not the base's point under it,
  // which the tilt moves 15 mm x 2.5e-3 sideways), to the ray's 1e-6.
  EXPECT_NEAR(scene.TrueHeightAt(57.5, 0.0), hit.point_in_world.z(), 1e-6);
  EXPECT_TRUE(scene.OnPart(57.5, 0.0));
  EXPECT_FALSE(scene.OnPart(61.0, 0.0));
}

}  // namespace
}  // namespace insitu::sim
