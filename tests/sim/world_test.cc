#include "insitu/sim/world.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

namespace insitu::sim {
namespace {

WorldOptions SmallWorld() {
  WorldOptions w;
  w.part.kind = "plane";
  return w;
}

double Mean(const Frame& f) {
  double s = 0;
  for (int v = 0; v < f.height; ++v)
    for (int u = 0; u < f.width; ++u) s += f.at(u, v);
  return s / (static_cast<double>(f.width) * f.height);
}

// A frame takes its exposure, then its bytes cross the camera's link (118 MB/s: GigE less its
// framing): 612 x 512 binned 8-bit pixels, 313,344 bytes, 2.655 ms.
TEST(SimWorld, GrabAdvancesTheClockByTheExposureAndTheLink) {
  SimWorld w(SmallWorld());
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.SetExposure(20000).ok());
  const double t0 = w.now_s();
  auto f = w.Grab();
  ASSERT_TRUE(f.ok());
  EXPECT_NEAR(w.now_s() - t0, 0.02 + 612.0 * 512.0 / 118e6, 1e-12);
  EXPECT_EQ(f->width, 2448 / 4);
  EXPECT_EQ(f->height, 2048 / 4);
}

// A region of interest: the frame holds the band's rows, exactly those of the whole frame, says
// where it lies, and crosses the link in the band's share of the time.
TEST(SimWorld, ARegionIsTheWholeFramesBandAndTravelsFaster) {
  SimWorld whole(SmallWorld()), band(SmallWorld());
  for (SimWorld* w : {&whole, &band}) {
    ASSERT_TRUE(w->SetBinning(4).ok());
    ASSERT_TRUE(w->SetExposure(20000).ok());
  }
  ASSERT_TRUE(band.SetRegion(800, 400).ok());  // binned rows 200..300
  EXPECT_EQ(band.SetRegion(2000, 100).code(), StatusCode::kOutOfRange);
  const double t0 = band.now_s();
  auto a = whole.Grab();
  auto b = band.Grab();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(b->offset_y, 200);
  EXPECT_EQ(b->height, 100);
  EXPECT_NEAR(band.now_s() - t0, 0.02 + 612.0 * 100.0 / 118e6, 1e-12);
  for (int v = 0; v < b->height; v += 7) {
    for (int u = 0; u < b->width; u += 13) ASSERT_EQ(b->at(u, v), a->at(u, v + 200)) << u << "," << v;
  }
}

// Ambient light scales with exposure (linear sensor, no stripe): doubling the exposure
// doubles the mean signal above the ~0.5 DN rounding floor, within shot noise.
TEST(SimWorld, AmbientSignalIsLinearInExposure) {
  WorldOptions o = SmallWorld();
  o.light.ambient_lux = 3000;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.SetExposure(10000).ok());
  const double m1 = Mean(*w.Grab());
  ASSERT_TRUE(w.SetExposure(20000).ok());
  const double m2 = Mean(*w.Grab());
  EXPECT_GT(m1, 5.0);
  EXPECT_NEAR(m2 / m1, 2.0, 0.05);
}

TEST(SimWorld, StripeAppearsOnlyWhileThePointerRuns) {
  SimWorld w(SmallWorld());
  ASSERT_TRUE(w.SetBinning(2).ok());
  auto dark = w.Grab();
  EXPECT_EQ(w.last_truth().samples, 0);
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  w.Advance(0.005);
  auto lit = w.Grab();
  EXPECT_GT(w.last_truth().samples, 1000);
  const int max_dark = *std::max_element(dark->bytes.begin(), dark->bytes.end());
  const int max_lit = *std::max_element(lit->bytes.begin(), lit->bytes.end());
  EXPECT_GT(max_lit, max_dark + 50);
}

TEST(SimWorld, SaturationClipsAtFullScale) {
  WorldOptions o = SmallWorld();
  o.scan_head.pointer.power_mw = 5.0;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(2).ok());
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  auto f = w.Grab();
  EXPECT_EQ(*std::max_element(f->bytes.begin(), f->bytes.end()), 255);
}

TEST(SimWorld, TwelveBitFramesUseSixteenBitSamples) {
  WorldOptions o = SmallWorld();
  o.camera.bit_depth = 12;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  auto f = w.Grab();
  EXPECT_EQ(f->bytes.size(), static_cast<size_t>(f->width) * f->height * 2);
  int mx = 0;
  for (int v = 0; v < f->height; ++v)
    for (int u = 0; u < f->width; ++u) mx = std::max(mx, f->at(u, v));
  EXPECT_GT(mx, 255);
  EXPECT_LE(mx, 4095);
}

// The 15 mm step hides the plate behind it from the camera: some beam samples are occluded.
TEST(SimWorld, TallStepOccludesTheStripeBehindIt) {
  WorldOptions o;
  SimWorld w(o);
  ASSERT_TRUE(w.SetBinning(4).ok());
  ASSERT_TRUE(w.StartPointerLine({12.0, -30, 0}, {12.0, 30, 0}, 5000).ok());
  (void)w.Grab();
  EXPECT_GT(w.last_truth().occluded_samples, w.last_truth().samples / 2);
}

TEST(SimWorld, RefusesCommandsOutsideItsLimits) {
  SimWorld w(SmallWorld());
  EXPECT_EQ(w.StartPointerLine({0, -90, 0}, {0, 30, 0}, 5000).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.StartPointerLine({0, 0, 40}, {0, 30, 40}, 5000).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.MoveStage(25.0).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.SetExposure(-5).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(w.SetBinning(3).code(), StatusCode::kInvalidArgument);
}

TEST(SimWorld, SameSeedSameFrame) {
  SimWorld a(SmallWorld()), b(SmallWorld());
  for (SimWorld* w : {&a, &b}) {
    ASSERT_TRUE(w->SetBinning(4).ok());
    ASSERT_TRUE(w->StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000).ok());
  }
  EXPECT_EQ(a.Grab()->bytes, b.Grab()->bytes);
}

// ---------------------------------------------------------------------------------------------
// The shop floor's light (each off by default).

// The gray level at a world point of a noise-free full-resolution frame (the pixel it projects
// to, averaged over 3 x 3 for the rounding).
double LevelAt(const SimWorld& w, const Frame& f, const Eigen::Vector3d& p) {
  Eigen::Vector2d px;
  EXPECT_TRUE(w.true_camera().Project(p, &px));
  double sum = 0;
  for (int dv = -1; dv <= 1; ++dv) {
    for (int du = -1; du <= 1; ++du) {
      sum += f.at(static_cast<int>(std::lround(px.x())) + du,
                  static_cast<int>(std::lround(px.y())) + dv);
    }
  }
  return sum / 9.0;
}

// The frame a world takes of the pointer's line x = x_mm from y0 to y1 (after 5 ms of sweeping),
// at `exposure_us` (0: the camera's own).
Frame LineFrame(const WorldOptions& opts, double x_mm, double y0, double y1,
                double exposure_us = 0.0) {
  SimWorld w(opts);
  if (exposure_us > 0) {
    EXPECT_TRUE(w.SetExposure(exposure_us).ok());
  }
  EXPECT_TRUE(w.StartPointerLine({x_mm, y0, 0}, {x_mm, y1, 0}, 5000).ok());
  w.Advance(0.005);
  auto f = w.Grab();
  EXPECT_TRUE(f.ok());
  return f.ok() ? *f : Frame{};
}

WorldOptions Quiet() {
  WorldOptions o;
  o.part.kind = "none";
  o.camera.noise = false;
  o.light.speckle_contrast = 0.0;
  o.light.ambient_lux = 0.0;
  return o;
}

// A lamp: illuminance lamp_lux at the origin, falling as the squared distance and the cosine
// of incidence. On the flat plate lit from (-300, 0, 300), the levels at x = -60 and x = +60
// stand in the ratio of E = L (d0 / d)^2 cos(incidence) at the two points (1.52).
TEST(SimWorld, ALampLightsAsTheInverseSquareAndTheCosine) {
  WorldOptions o = Quiet();
  o.light.lamp_position_mm = {-300.0, 0.0, 300.0};
  o.light.lamp_lux = 3000.0;
  o.stage.plate_albedo = 0.5;
  SimWorld w(o);
  ASSERT_TRUE(w.SetExposure(20000).ok());
  auto f = w.Grab();
  ASSERT_TRUE(f.ok());
  const Eigen::Vector3d lamp(-300, 0, 300);
  auto expected = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d l = lamp - p;
    return lamp.squaredNorm() / l.squaredNorm() * l.normalized().z();
  };
  const Eigen::Vector3d a(-60, 0, 0), b(60, 0, 0);
  const double la = LevelAt(w, *f, a), lb = LevelAt(w, *f, b);
  ASSERT_GT(lb, 20.0);
  ASSERT_LT(la, 250.0);
  // The camera's cos^4 falloff differs by under 1 % between the two (both near its axis);
  // rounding 0.5 DN of ~50.
  EXPECT_NEAR(la / lb, expected(a) / expected(b), 0.03 * expected(a) / expected(b));
}

// A label on the plate reflects as its albedo says: 0.85 against the plate's 0.12 under the
// same room light.
TEST(SimWorld, ALabelOnThePlateShowsItsAlbedo) {
  WorldOptions o = Quiet();
  o.light.ambient_lux = 3000.0;
  o.stage.labels = {{20.0, 0.0, 20.0, 20.0, 0.85}};
  SimWorld w(o);
  ASSERT_TRUE(w.SetExposure(20000).ok());
  auto f = w.Grab();
  ASSERT_TRUE(f.ok());
  const double label = LevelAt(w, *f, {20, 0, 0}), plate = LevelAt(w, *f, {-20, 0, 0});
  ASSERT_GT(plate, 10.0);
  EXPECT_NEAR(label / plate, 0.85 / 0.12, 0.1 * 0.85 / 0.12);  // cos^4 and rounding
}

// A glossy part mirrors the pointer: on the arc's flank the mirrored beam leaves toward the
// camera where the surface tilts half the camera's angle (a glint: saturated), and a matte
// part of the same albedo shows no such spot.
TEST(SimWorld, AGlossyPartGlints) {
  WorldOptions o = Quiet();
  o.part.kind = "arc";
  o.part.albedo = 0.3;
  auto peak = [](const WorldOptions& opts) {
    const Frame f = LineFrame(opts, -7.4, -15, 15, 5000);
    return static_cast<int>(*std::max_element(f.bytes.begin(), f.bytes.end()));
  };
  const int matte = peak(o);
  o.part.specular = 0.5;
  const int glossy = peak(o);
  EXPECT_LT(matte, 120);
  EXPECT_EQ(glossy, 255);
}

// Interreflection: the pointer's spot lights the surfaces facing it. On the step gauge, with
// the line along its top steps, the walls beside the line gain light the matte single bounce
// does not give them, a few percent of the stripe's own level (E ~ albedo (P T / L) / (pi d)
// per unit area at d from the line, against P T / L over the stripe's ~0.25 mm).
TEST(SimWorld, InterreflectionLightsFacingSurfaces) {
  WorldOptions o = Quiet();
  o.part.kind = "step_gauge";
  o.part.albedo = 0.9;
  const Frame single = LineFrame(o, 3, -40, 40);
  o.light.interreflection = true;
  const Frame twice = LineFrame(o, 3, -40, 40);
  int brighter = 0, darker = 0;
  int stripe_max = 0, glow_max = 0;
  for (size_t i = 0; i < single.bytes.size(); ++i) {
    stripe_max = std::max<int>(stripe_max, single.bytes[i]);
    const int d = static_cast<int>(twice.bytes[i]) - single.bytes[i];
    brighter += d > 0;
    darker += d < 0;
    glow_max = std::max(glow_max, d);
  }
  EXPECT_EQ(darker, 0);       // light only adds
  EXPECT_GT(brighter, 1000);  // over an area, not a line
  EXPECT_GE(glow_max, 2);
  EXPECT_LT(glow_max, stripe_max / 5);
}

// A colour camera's mosaic: the pointer's red line shows in the red pixels at ~9x the green
// and ~18x the blue (the filters' passes for 680 nm).
TEST(SimWorld, AColourCameraSeesTheRedLineThroughItsRedFilters) {
  WorldOptions o = Quiet();
  o.part.kind = "plane";
  o.camera.pixel_format = "BayerRG";
  const Frame f = LineFrame(o, 0, -30, 30);
  EXPECT_EQ(f.format, PixelFormat::kBayerRG);
  double sum[3] = {0, 0, 0};
  for (int v = 0; v < f.height; ++v) {
    for (int u = 0; u < f.width; ++u) {
      const int filter = (v % 2 == 0) ? (u % 2 == 0 ? 0 : 1) : (u % 2 == 0 ? 1 : 2);
      sum[filter] += f.at(u, v) * (filter == 1 ? 0.5 : 1.0);  // two greens per quad
    }
  }
  EXPECT_NEAR(sum[0] / sum[1], 0.9 / 0.10, 0.15 * 0.9 / 0.10);
  EXPECT_NEAR(sum[0] / sum[2], 0.9 / 0.05, 0.2 * 0.9 / 0.05);
}

TEST(WorldOptions, ValidateNamesTheField) {
  WorldOptions o;
  o.camera.exposure_ms = -1;
  const Status st = o.Validate();
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("camera: exposure_ms"), std::string::npos) << st.message();
}

}  // namespace
}  // namespace insitu::sim
