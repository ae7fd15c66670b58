#include "insitu/core/robust.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace insitu {
namespace {

TEST(Robust, MedianOfAnOddCountIsTheMiddleValue) {
  EXPECT_EQ(Median(std::vector<double>{5.0, -1.0, 3.0, 9.0, 2.0}), 3.0);
  EXPECT_EQ(Median(std::vector<double>{7.0}), 7.0);
}

TEST(Robust, MedianOfAnEvenCountIsTheUpperMiddleValue) {
  // Rank n / 2 of the sorted sample (1, 2, 3, 4): 3, not the mean 2.5.
  EXPECT_EQ(Median(std::vector<double>{4.0, 1.0, 3.0, 2.0}), 3.0);
  EXPECT_EQ(Median(std::vector<float>{2.0f, 1.0f}), 2.0);
}

TEST(Robust, EmptySampleGivesNaN) {
  EXPECT_TRUE(std::isnan(Median(std::vector<double>{})));
  EXPECT_TRUE(std::isnan(Median(std::vector<float>{})));
  EXPECT_TRUE(std::isnan(MedianAbsDeviation(std::vector<double>{})));
  EXPECT_TRUE(std::isnan(MedianAbsDeviationFrom(std::vector<double>{}, 0.0)));
}

TEST(Robust, MedianLeavesItsArgumentAloneAndInPlaceReordersIt) {
  const std::vector<double> given{3.0, 1.0, 2.0};
  std::vector<double> copy = given;
  EXPECT_EQ(Median(copy), 2.0);
  EXPECT_EQ(copy, given);
  EXPECT_EQ(MedianInPlace(copy), 2.0);
  EXPECT_EQ(copy[1], 2.0);  // nth_element puts the median at its rank
}

TEST(Robust, MedianAbsDeviation) {
  // Median 3; |v - 3| = (2, 1, 0, 6, 97): median 2. The outlier 100 moves neither.
  EXPECT_EQ(MedianAbsDeviation(std::vector<double>{1.0, 2.0, 3.0, 9.0, 100.0}), 2.0);
  EXPECT_EQ(MedianAbsDeviation(std::vector<float>{1.0f, 2.0f, 3.0f, 9.0f, 100.0f}), 2.0);
  // About zero: |v| = (1, 2, 3, 9, 100) -> 3.
  EXPECT_EQ(MedianAbsDeviationFrom(std::vector<double>{-1.0, 2.0, -3.0, 9.0, 100.0}, 0.0), 3.0);
  EXPECT_EQ(MedianAbsDeviationFrom(std::vector<float>{-1.0f, 2.0f, -3.0f, 9.0f, 100.0f}, 0.0f),
            3.0);
}

TEST(Robust, MadEstimatesAGaussianSigmaThroughOutliers) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(10.0, 2.0);
  std::vector<double> v;
  for (int i = 0; i < 20000; ++i) v.push_back(noise(rng));
  for (int i = 0; i < 1000; ++i) v.push_back(1e6);  // 5 % gross outliers
  // The outliers move the median to rank 10500 of the 20000 good values, the 52.5 % quantile:
  // 10 + 2 * 0.0627 = 10.125. The sample median's standard error is 1.2533 * 2 / sqrt(20000) =
  // 0.018; 0.06 is over 3 of them.
  EXPECT_NEAR(Median(v), 10.125, 0.06);
  // Likewise the MAD is the 52.5 % quantile of |x - median|, 2 * 0.7144 = 1.429 (0.6745 without
  // the outliers), and kMadToSigma times it 2.118. Its relative standard error is about
  // 1.17 / sqrt(20000) = 0.8 %, 0.017; 0.05 is 3 of them.
  EXPECT_NEAR(kMadToSigma * MedianAbsDeviation(v), 2.118, 0.05);
}

}  // namespace
}  // namespace insitu
