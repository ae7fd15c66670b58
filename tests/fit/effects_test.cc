// The effect library against the forms of CONTRACT.md ("Canonical effects"): each effect's
// Apply on hand-picked points, which data each applies to, and the starting values it derives
// from a residual.
#include "insitu/fit/effects.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>
#include <vector>

namespace insitu::fit {
namespace {

using Eigen::Vector2d;

const std::vector<std::string> kCanonical = {
    "offset",      "scale",         "rotation",      "skew",
    "mirror_separation", "lens_radial", "head_geometry", "perspective",
    "thermal_drift", "tracking_lag", "focus_scale"};

std::unique_ptr<Effect> Make(const std::string& name) {
  std::unique_ptr<Effect> e = MakeEffect(name);
  EXPECT_NE(e, nullptr) << name;
  return e;
}

// A point with every column set, and a modelled position that is not the command, so that an
// effect acting on the command is told apart from one acting on the position so far.
FieldPoint HandPoint() {
  FieldPoint p;
  p.cmd = Vector2d(30.0, -20.0);
  p.z_cmd_mm = 4.0;
  p.t_s = 100.0;
  p.v_mm_s = Vector2d(300.0, -400.0);
  return p;
}
const Vector2d kUv0(30.5, -19.25);

Vector2d Applied(const std::string& name, const std::vector<double>& params,
                 const FieldPoint& p = HandPoint(), const Vector2d& uv0 = kUv0) {
  std::unique_ptr<Effect> e = Make(name);
  EXPECT_EQ(e->param_names().size(), params.size()) << name;
  Vector2d uv = uv0;
  e->Apply(p, params.data(), &uv);
  return uv;
}

void ExpectVec(const Vector2d& got, const Vector2d& want) {
  EXPECT_NEAR(got.x(), want.x(), 1e-12 * (1.0 + std::abs(want.x())));
  EXPECT_NEAR(got.y(), want.y(), 1e-12 * (1.0 + std::abs(want.y())));
}

TEST(EffectLibrary, HoldsTheTenCanonicalEffectsInOrder) {
  const std::vector<std::unique_ptr<Effect>> lib = EffectLibrary();
  ASSERT_GE(lib.size(), kCanonical.size());
  std::set<std::string> names;
  for (size_t i = 0; i < lib.size(); ++i) {
    if (i < kCanonical.size()) {
      EXPECT_EQ(lib[i]->name(), kCanonical[i]);
    }
    EXPECT_TRUE(names.insert(lib[i]->name()).second) << "twice: " << lib[i]->name();
    EXPECT_FALSE(lib[i]->meaning().empty()) << lib[i]->name();
    EXPECT_EQ(lib[i]->meaning().find('\n'), std::string::npos) << "one line: " << lib[i]->name();
  }
}

TEST(EffectLibrary, ParameterNamesAndStagesFollowTheContract) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> params = {
      {"offset", {"dx", "dy"}},
      {"scale", {"sx", "sy"}},
      {"rotation", {"theta"}},
      {"skew", {"gamma"}},
      {"mirror_separation", {"kappa", "x0", "y0"}},
      {"lens_radial", {"k", "x0", "y0"}},
      {"perspective", {"p", "q"}},
      {"thermal_drift", {"ox", "oy", "g"}},
      {"tracking_lag", {"tau"}},
      {"focus_scale", {"c"}},
      {"head_distortion", {"kappa", "k", "x0", "y0"}}};
  for (const auto& [name, want] : params) {
    const std::unique_ptr<Effect> e = Make(name);
    EXPECT_EQ(e->param_names(), want) << name;
    const int stage = name == "rotation" ? 1 : name == "perspective" ? 2 : 0;
    EXPECT_EQ(e->stage(), stage) << name;
  }
}

TEST(EffectLibrary, MakeEffectByName) {
  for (const std::string& name : kCanonical) EXPECT_EQ(Make(name)->name(), name);
  EXPECT_EQ(MakeEffect("no_such_effect"), nullptr);
  EXPECT_EQ(MakeEffect(""), nullptr);
  EXPECT_EQ(MakeEffect("Offset"), nullptr);
}

// Each form written out from the contract's table on the hand point: cmd (30, -20), z 4 mm,
// t 100 s, v (300, -400) mm/s, position so far (30.5, -19.25).
TEST(EffectApply, OffsetScaleSkewAddToThePosition) {
  ExpectVec(Applied("offset", {0.05, -0.02}), {30.55, -19.27});
  ExpectVec(Applied("scale", {2e-3, -1e-3}), {30.5 + 2e-3 * 30.0, -19.25 + -1e-3 * -20.0});
  ExpectVec(Applied("skew", {5e-4}), {30.5 + 5e-4 * -20.0, -19.25});
}

TEST(EffectApply, RotationTurnsThePositionAboutTheOrigin) {
  const double t = 0.01, c = std::cos(t), s = std::sin(t);
  ExpectVec(Applied("rotation", {t}), {c * 30.5 - s * -19.25, s * 30.5 + c * -19.25});
  ExpectVec(Applied("rotation", {M_PI / 2}), {19.25, 30.5});
  ExpectVec(Applied("rotation", {0.0}), kUv0);
  // The cached sin/cos follow the angle from call to call.
  ExpectVec(Applied("rotation", {-t}), {c * 30.5 + s * -19.25, -s * 30.5 + c * -19.25});
}

TEST(EffectApply, MirrorSeparationIsThePincushionInX) {
  // u += kappa (x - x0) (y - y0)^2 = 1e-6 * (30 - 2) * (-20 + 1)^2 = 1.0108e-2
  ExpectVec(Applied("mirror_separation", {1e-6, 2.0, -1.0}), {30.5 + 1.0108e-2, -19.25});
  // On the centre lines nothing moves.
  FieldPoint on_axis = HandPoint();
  on_axis.cmd = Vector2d(2.0, 40.0);
  ExpectVec(Applied("mirror_separation", {1e-6, 2.0, -1.0}, on_axis), kUv0);
}

TEST(EffectApply, LensRadialIsRadialAboutItsCentre) {
  // d = (30 - 2, -20 + 1) = (28, -19), r^2 = 784 + 361 = 1145
  const double k = 2e-7;
  ExpectVec(Applied("lens_radial", {k, 2.0, -1.0}),
            {30.5 + k * 1145.0 * 28.0, -19.25 + k * 1145.0 * -19.0});
}

TEST(EffectApply, PerspectiveDividesByTheCommandedPlane) {
  const double w = 1.0 + 1e-4 * 30.0 + -2e-4 * -20.0;  // 1.007
  ExpectVec(Applied("perspective", {1e-4, -2e-4}), {30.5 / w, -19.25 / w});
}

TEST(EffectApply, ThermalDriftGrowsWithTime) {
  // u += t (ox + g x), v += t (oy + g y)
  ExpectVec(Applied("thermal_drift", {1e-4, -2e-4, 1e-6}),
            {30.5 + 100.0 * (1e-4 + 1e-6 * 30.0), -19.25 + 100.0 * (-2e-4 + 1e-6 * -20.0)});
}

TEST(EffectApply, TrackingLagTrailsTheVelocity) {
  ExpectVec(Applied("tracking_lag", {1e-4}), {30.5 - 1e-4 * 300.0, -19.25 - 1e-4 * -400.0});
}

TEST(EffectApply, FocusScaleGrowsWithZ) {
  ExpectVec(Applied("focus_scale", {1e-4}),
            {30.5 + 1e-4 * 4.0 * 30.0, -19.25 + 1e-4 * 4.0 * -20.0});
}

TEST(EffectApplicable, NeedsItsColumn) {
  FieldData bare;
  bare.points.push_back(HandPoint());
  for (const std::string& name : kCanonical) {
    const bool needs = name == "thermal_drift" || name == "tracking_lag" || name == "focus_scale";
    EXPECT_EQ(Make(name)->Applicable(bare), !needs) << name;
  }
  FieldData with_t = bare, with_v = bare, with_z = bare;
  with_t.has_t = with_v.has_v = with_z.has_z = true;
  EXPECT_TRUE(Make("thermal_drift")->Applicable(with_t));
  EXPECT_FALSE(Make("thermal_drift")->Applicable(with_v));
  EXPECT_TRUE(Make("tracking_lag")->Applicable(with_v));
  EXPECT_FALSE(Make("tracking_lag")->Applicable(with_z));
  EXPECT_TRUE(Make("focus_scale")->Applicable(with_z));
  EXPECT_FALSE(Make("focus_scale")->Applicable(with_t));
}

// A 9 x 9 grid over x -30..50, y -40..40 (centroid (10, 0), not the commanded origin), with
// time, velocity and focus columns varying independently of position.
FieldData OffCentreGrid() {
  FieldData data;
  data.has_t = data.has_v = data.has_z = true;
  int i = 0;
  for (int r = 0; r < 9; ++r) {
    for (int c = 0; c < 9; ++c, ++i) {
      FieldPoint p;
      p.cmd = Vector2d(-30.0 + 10.0 * c, -40.0 + 10.0 * r);
      p.t_s = 7.0 * i;
      p.v_mm_s = 1000.0 * Vector2d(std::cos(2.4 * i), std::sin(2.4 * i));
      p.z_cmd_mm = 5.0 * ((3 * i) % 5 - 2);
      data.points.push_back(p);
    }
  }
  return data;
}

// Starting values from the residual the effect alone leaves (model so far = the command) plus
// an unmodelled offset of (0.1, -0.2) mm, which must not leak into them. The effects linear in
// their parameters start at the exact values; rotation and perspective at their first-order
// values (relative error ~ theta = 1e-3, resp. p x ~ 1e-4 * 50 = 5e-3; 2 % allowed); centres
// at the centroid of the commands.
TEST(EffectInitial, StartsFromTheResidual) {
  const std::vector<std::pair<std::string, std::vector<double>>> truth = {
      {"scale", {2e-3, -1.5e-3}},
      {"rotation", {1e-3}},
      {"skew", {5e-4}},
      {"mirror_separation", {1.5e-6, 10.0, 0.0}},
      {"lens_radial", {2e-7, 10.0, 0.0}},
      {"perspective", {1e-4, -5e-5}},
      {"thermal_drift", {1e-4, -5e-5, 2e-6}},
      {"tracking_lag", {1e-4}},
      {"focus_scale", {1e-4}}};
  const Vector2d unmodelled(0.1, -0.2);
  for (const auto& [name, params] : truth) {
    SCOPED_TRACE(name);
    const std::unique_ptr<Effect> e = Make(name);
    FieldData data = OffCentreGrid();
    std::vector<Vector2d> residual;
    for (FieldPoint& p : data.points) {
      Vector2d uv = p.cmd;
      e->Apply(p, params.data(), &uv);
      p.meas = uv + unmodelled;
      residual.push_back(p.meas - p.cmd);
    }
    const std::vector<double> init = e->Initial(data, residual);
    ASSERT_EQ(init.size(), params.size());
    const bool first_order = name == "rotation" || name == "perspective";
    for (size_t j = 0; j < params.size(); ++j) {
      const double tol = (first_order ? 0.02 : 1e-9) * std::abs(params[j]) + 1e-12;
      EXPECT_NEAR(init[j], params[j], tol) << e->param_names()[j];
    }
  }
}

TEST(EffectInitial, OffsetIsTheMeanResidual) {
  FieldData data = OffCentreGrid();
  std::vector<Vector2d> residual(data.points.size(), Vector2d(0.05, -0.03));
  residual[0] += Vector2d(0.81, 0.0);  // mean x grows by 0.81 / 81 = 0.01
  const std::vector<double> init = Make("offset")->Initial(data, residual);
  EXPECT_NEAR(init[0], 0.06, 1e-12);
  EXPECT_NEAR(init[1], -0.03, 1e-12);
}

// A column the data lacks (all zero) gives a zero start, not NaN.
TEST(EffectInitial, ZeroWhereTheDataSaysNothing) {
  FieldData data = OffCentreGrid();
  for (FieldPoint& p : data.points) p.z_cmd_mm = 0.0;
  const std::vector<Vector2d> residual(data.points.size(), Vector2d(0.01, 0.02));
  EXPECT_EQ(Make("focus_scale")->Initial(data, residual), std::vector<double>{0.0});
  const FieldData empty;
  for (const std::string& name : kCanonical) {
    const std::vector<double> init = Make(name)->Initial(empty, {});
    for (double v : init) EXPECT_TRUE(std::isfinite(v)) << name;
  }
}

}  // namespace
}  // namespace insitu::fit
