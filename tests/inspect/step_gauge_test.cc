#include "insitu/inspect/step_gauge.h"

#include <cmath>

#include <gtest/gtest.h>

namespace insitu::inspect {
namespace {

// A synthetic cloud: lines every 0.5 mm in x; points at the centres of 0.1 mm columns along
// the gauge's length (as camera columns sample it), each step's top raised by a known error.
geometry::Cloud SyntheticGauge(const std::vector<double>& errors) {
  geometry::Cloud cloud;
  const double heights[] = {3, 5, 10, 15};
  int line = 0;
  for (double x = -9.75; x < 10; x += 0.5, ++line) {
    const int step = static_cast<int>(std::floor((x + 10) / 5));
    for (double y = -39.95; y < 40.0; y += 0.1) {
      geometry::CloudPoint p;
      p.point_in_galvo = Eigen::Vector3f(x, y, heights[step] + errors[step]);
      p.line = line;
      cloud.push_back(p);
    }
  }
  return cloud;
}

TEST(StepGauge, RecoversKnownStepErrorsAndLength) {
  auto r = EvaluateStepGauge(SyntheticGauge({0.01, -0.02, 0.03, -0.04}), StepGaugeSpec{});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->steps.size(), 4u);
  EXPECT_NEAR(r->steps[0].mean_error_mm, 0.01, 1e-6);
  EXPECT_NEAR(r->steps[3].mean_error_mm, -0.04, 1e-6);
  EXPECT_NEAR(r->max_abs_error_mm, 0.04, 1e-6);
  EXPECT_NEAR(r->length_mm, 80.0, 1e-4);
  EXPECT_NEAR(r->length_std_mm, 0.0, 1e-3);
  EXPECT_GT(r->length_lines, 20);
}

TEST(StepGauge, WrongPlacementIsAnError) {
  StepGaugeSpec spec;
  spec.center_x_mm = 100.0;
  EXPECT_FALSE(EvaluateStepGauge(SyntheticGauge({0, 0, 0, 0}), spec).ok());
  spec.center_x_mm = 0.0;
  spec.edge_margin_mm = 3.0;  // wider than half a step
  EXPECT_FALSE(spec.Validate().ok());
}

}  // namespace
}  // namespace insitu::inspect
