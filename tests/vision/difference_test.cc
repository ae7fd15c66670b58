#include "insitu/vision/difference.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace insitu::vision {
namespace {

// A 64 x 64 view at gray level 120 with Gaussian noise of sigma 2 in both frames (rounded to
// whole levels), and a 6 x 6 mark 30 levels darker after. The difference's noise is about
// 2 * sqrt(2) = 2.8 (its MAD on whole levels: 2, sigma 2.97), a 3 x 3 mean of it 0.99, the
// threshold 5 of those: 4.9. Every pixel of the mark has at least 4 of its 9 in the mark (a
// corner): a mean of 13.3, 8 sigmas above it. A pixel two away from the mark has none: a false
// detection there needs a 5-sigma excursion, p = 3e-7 per pixel, none in 4096.
TEST(FindDarkened, FindsTheMarkAndNothingElse) {
  constexpr int kSize = 64;
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 2.0);
  std::vector<uint8_t> before(kSize * kSize), after(kSize * kSize);
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      const bool mark = x >= 30 && x < 36 && y >= 20 && y < 26;
      before[y * kSize + x] = static_cast<uint8_t>(std::lround(120 + noise(rng)));
      after[y * kSize + x] = static_cast<uint8_t>(std::lround(120 - (mark ? 30 : 0) + noise(rng)));
    }
  }
  auto dark =
      FindDarkened({before.data(), kSize, kSize, kSize, 8}, {after.data(), kSize, kSize, kSize, 8});
  ASSERT_TRUE(dark.ok()) << dark.status().ToString();
  ASSERT_EQ(dark->px.size(), dark->depth.size());
  int in_mark = 0;
  for (size_t i = 0; i < dark->px.size(); ++i) {
    const Eigen::Vector2d& p = dark->px[i];
    // Within the mark or one pixel around it (where the 3 x 3 mean sees 1 to 3 of it).
    EXPECT_TRUE(p.x() >= 29 && p.x() <= 36 && p.y() >= 19 && p.y() <= 26) << p.transpose();
    if (p.x() >= 30 && p.x() < 36 && p.y() >= 20 && p.y() < 26) {
      ++in_mark;
      // d itself: 30 levels and the difference's noise, within 4 sigmas.
      EXPECT_NEAR(dark->depth[i], 30.0, 4 * 2.97) << p.transpose();
    }
  }
  EXPECT_EQ(in_mark, 36);
}

TEST(FindDarkened, RefusesViewsOfDifferentSizes) {
  const std::vector<uint8_t> a(16, 0);
  EXPECT_EQ(FindDarkened({a.data(), 4, 4, 4, 8}, {a.data(), 2, 2, 4, 8}).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::vision
