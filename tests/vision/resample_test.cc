#include "insitu/vision/resample.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace insitu::vision {
namespace {

TEST(Remap, SamplesBilinearlyAndReadsZeroOutside) {
  // 16-bit samples (12-bit values): 0, 100 / 200, 300.
  const std::vector<uint16_t> samples{0, 100, 200, 300};
  const ImageView image{samples.data(), 2, 2, 4, 12};
  PixelMap map{3, 1, {0.5f, 1.0f, 5.0f}, {0.5f, 0.0f, 5.0f}};
  auto out = Remap(image, map);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  EXPECT_EQ(out->bit_depth, 12);
  const ImageView v = out->view();
  EXPECT_EQ(v.row16(0)[0], 150);  // the mean of all four
  EXPECT_EQ(v.row16(0)[1], 100);  // on a pixel centre
  EXPECT_EQ(v.row16(0)[2], 0);    // outside
}

TEST(Remap, RefusesAMapOfTheWrongSize) {
  const std::vector<uint8_t> samples(4, 7);
  const ImageView image{samples.data(), 2, 2, 2, 8};
  EXPECT_EQ(Remap(image, PixelMap{2, 2, {0, 0, 0}, {0, 0, 0, 0}}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(Remap(ImageView{}, PixelMap{1, 1, {0}, {0}}).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::vision
