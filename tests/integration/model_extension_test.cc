// Closing the loop on the simulated head: the world carries a library effect (a two-mirror
// pincushion with its centre off the origin, as measured reality might), its field is measured
// the way a field calibration would (where do commanded spots land, with 2 um of measuring
// noise), insitu diagnose names the effect, the diagnosis is saved as a model extension, and
// the galvo list corrected by it marks where it should.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <vector>

#include "insitu/fit/diagnose.h"
#include "insitu/fit/extension.h"
#include "insitu/sim/world.h"
#include "support/landed_spot.h"

namespace insitu {
namespace {

sim::WorldOptions HeadWithPincushion() {
  sim::WorldOptions w;
  w.part.kind = "none";  // the plate at z = 0
  w.scan_head.field_effects = {{"mirror_separation", {3e-6, 5.0, -8.0}}};
  return w;
}

using testing::LandedSpot;

TEST(ModelExtension, DiagnosedEffectCorrectsTheMarks) {
  const sim::WorldOptions o = HeadWithPincushion();
  ASSERT_TRUE(o.Validate().ok());
  fit::FieldData data;
  data.origin = "<measured on the simulated head>";
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.002);
  for (int j = 0; j < 9; ++j) {
    for (int i = 0; i < 9; ++i) {
      fit::FieldPoint p;
      p.cmd = {-40.0 + 10.0 * i, -40.0 + 10.0 * j};
      p.meas = LandedSpot(o, p.cmd) + Eigen::Vector2d(noise(rng), noise(rng));
      data.points.push_back(p);
    }
  }
  auto d = fit::Diagnose(data);
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  ASSERT_FALSE(d->cause.empty()) << d->Summary();
  EXPECT_EQ(d->cause.front(), "mirror_separation") << d->Summary();
  std::printf("%s\n", d->Summary().c_str());

  // Saved and read back as the mark job would.
  auto ext = fit::ModelExtension::FromDiagnosis(*d);
  ASSERT_TRUE(ext.ok());
  const std::string path =
      (std::filesystem::temp_directory_path() / "insitu_extension.yaml").string();
  ASSERT_TRUE(fit::SaveExtension(*ext, data.origin, path).ok());
  auto loaded = fit::LoadExtension(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();

  double raw = 0.0, corrected = 0.0;
  for (const Eigen::Vector2d& target :
       {Eigen::Vector2d(35.0, 32.0), Eigen::Vector2d(-37.5, 18.0), Eigen::Vector2d(12.0, -36.0),
        Eigen::Vector2d(-25.0, -25.0)}) {
    raw = std::max(raw, (LandedSpot(o, target) - target).norm());
    corrected = std::max(corrected, (LandedSpot(o, loaded->Inverse(target)) - target).norm());
  }
  // Uncorrected, kappa (x - 5)(y + 8)^2 is 0.02 to 0.14 mm at these points. Corrected, what is
  // left is the fit's error: 2 um noise over 81 points pins kappa to ~1 % and the centre to
  // ~0.3 mm, a few um at the field's edge. 10 um bounds it.
  EXPECT_GT(raw, 0.1);
  EXPECT_LT(corrected, 0.01);
  std::printf("worst mark error: %.4f mm uncorrected, %.4f mm with the extension\n", raw,
              corrected);
}

TEST(ModelExtension, BadFilesAndEffectsAreNamed) {
  EXPECT_FALSE(fit::ModelExtension::Make({{"wobble", {1.0}}}).ok());
  EXPECT_FALSE(fit::ModelExtension::Make({{"offset", {1.0}}}).ok());
  sim::WorldOptions o;
  o.scan_head.field_effects = {{"rotation", {0.1, 0.2}}};
  const Status st = o.Validate();
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("field_effects"), std::string::npos) << st.message();
  const std::string path =
      (std::filesystem::temp_directory_path() / "insitu_bad_ext.yaml").string();
  { std::ofstream(path) << "version: 1\neffects:\n  - name: offset\n    params: [0.1]\n"; }
  auto bad = fit::LoadExtension(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("insitu_bad_ext.yaml"), std::string::npos);
}

}  // namespace
}  // namespace insitu
