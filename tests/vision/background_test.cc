// The room's light taken off a frame (vision/background.h): the mean of the pointer-off frames,
// the subtraction floored at 0 with full scale kept, and what it does for a stripe beside a lit
// surface.
#include "insitu/vision/background.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "insitu/vision/stripe.h"

namespace insitu::vision {
namespace {

Image Filled(int w, int h, int depth, int value) {
  Image im;
  im.width = w;
  im.height = h;
  im.bit_depth = depth;
  im.bytes.assign(static_cast<size_t>(w) * h * (depth == 8 ? 1 : 2), 0);
  for (int i = 0; i < w * h; ++i) {
    if (depth == 8) {
      im.bytes[i] = static_cast<uint8_t>(value);
    } else {
      const uint16_t v = static_cast<uint16_t>(value);
      std::memcpy(&im.bytes[2 * i], &v, 2);
    }
  }
  return im;
}

int At(const Image& im, int u, int v) {
  const ImageView view = im.view();
  return view.is_8bit() ? view.row8(v)[u] : view.row16(v)[u];
}

TEST(Background, TheMeanOfFramesIsRoundedToTheNearestLevel) {
  const Image a = Filled(4, 3, 8, 10), b = Filled(4, 3, 8, 11), c = Filled(4, 3, 8, 13);
  auto mean = AverageFrames({a.view(), b.view(), c.view()});
  ASSERT_TRUE(mean.ok()) << mean.status().ToString();
  EXPECT_EQ(At(*mean, 2, 1), 11);  // 11.33
  const Image d = Filled(4, 3, 12, 4000), e = Filled(4, 3, 12, 4002);
  auto deep = AverageFrames({d.view(), e.view()});
  ASSERT_TRUE(deep.ok());
  EXPECT_EQ(deep->bit_depth, 12);
  EXPECT_EQ(At(*deep, 3, 2), 4001);
}

TEST(Background, FramesThatDoNotMatchAreRefusedByName) {
  const Image a = Filled(4, 3, 8, 10), b = Filled(5, 3, 8, 10), c = Filled(4, 3, 12, 10);
  EXPECT_EQ(AverageFrames({}).status().code(), StatusCode::kInvalidArgument);
  auto sizes = AverageFrames({a.view(), b.view()});
  ASSERT_FALSE(sizes.ok());
  EXPECT_NE(sizes.status().message().find("frame 1"), std::string::npos)
      << sizes.status().message();
  Image out;
  EXPECT_EQ(SubtractBackground(a.view(), c.view(), &out).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(SubtractBackground(a.view(), ImageView{}, &out).code(), StatusCode::kInvalidArgument);
}

TEST(Background, SubtractionFloorsAtZeroAndKeepsAClippedSampleClipped) {
  Image frame = Filled(3, 1, 8, 40);
  frame.bytes[1] = 20;   // darker than the room's light: noise, floored at 0
  frame.bytes[2] = 255;  // clipped: stays at full scale, not 255 - 30
  const Image room = Filled(3, 1, 8, 30);
  Image out;
  ASSERT_TRUE(SubtractBackground(frame.view(), room.view(), &out).ok());
  EXPECT_EQ(At(out, 0, 0), 10);
  EXPECT_EQ(At(out, 1, 0), 0);
  EXPECT_EQ(At(out, 2, 0), 255);
  Image deep = Filled(2, 1, 12, 4095);
  const Image deep_room = Filled(2, 1, 12, 100);
  ASSERT_TRUE(SubtractBackground(deep.view(), deep_room.view(), &out).ok());
  EXPECT_EQ(At(out, 0, 0), 4095);
}

// A stripe on a surface whose lit side reaches into it: the room's light rises as a ramp across
// the stripe (a face turned toward the window). The threshold K = k gmax then takes the ramp's
// upper side into the run and the centroid moves toward it. With the room's light subtracted the
// centre is the one the same stripe gives in a dark room (eq. 7's own truncation bias included),
// up to the rounding of the two frames to whole gray levels: 0.03 px on a 60-level stripe.
TEST(Background, ALitSurfaceBesideTheStripeNoLongerPullsItsCentre) {
  const int w = 64, h = 80;
  const double centre = 40.3, sigma = 1.5, amplitude = 60.0;
  auto image = [&](bool stripe, bool room) {
    Image im = Filled(w, h, 8, 0);
    for (int v = 0; v < h; ++v) {
      // Room light: 20 gray levels above the stripe, 36 below it (under K), a ramp ~6 px wide.
      const double r = room ? 20.0 + 16.0 / (1.0 + std::exp(-(v - centre - 1.0) / 1.5)) : 0.0;
      const double d = v - centre;
      const double s = stripe ? amplitude * std::exp(-d * d / (2 * sigma * sigma)) : 0.0;
      for (int u = 0; u < w; ++u) {
        im.bytes[static_cast<size_t>(v) * w + u] =
            static_cast<uint8_t>(std::lround(std::min(255.0, r + s)));
      }
    }
    return im;
  };
  const Image frame = image(true, true), dark = image(false, true), alone = image(true, false);
  StripeOptions o;
  o.direction = StripeDirection::kColumns;
  StripeExtractor extractor(o);
  const int u = w / 2;
  StripeResult dark_room;
  ASSERT_TRUE(extractor.Extract(alone.view(), &dark_room).ok());
  ASSERT_EQ(dark_room.status[u], StripeStatus::kValid);
  const double reference = dark_room.v(u);
  StripeResult raw;
  ASSERT_TRUE(extractor.Extract(frame.view(), &raw).ok());
  Image clean;
  ASSERT_TRUE(SubtractBackground(frame.view(), dark.view(), &clean).ok());
  StripeResult subtracted;
  ASSERT_TRUE(extractor.Extract(clean.view(), &subtracted).ok());
  ASSERT_EQ(subtracted.status[u], StripeStatus::kValid);
  EXPECT_NEAR(subtracted.v(u), reference, 0.03);
  // Without it the extractor's own local background (a straight line between windows beside
  // the run) takes the ramp off: the centre stays within 0.03 px too (with K = k gmax and raw
  // weights the ramp pulled it by over 0.1 px, the column still valid).
  ASSERT_EQ(raw.status[u], StripeStatus::kValid);
  EXPECT_NEAR(raw.v(u), reference, 0.03) << raw.v(u) << " vs " << reference;
}

// A colour frame (three samples a pixel, or a mosaic) is averaged and subtracted sample by
// sample and keeps its format, so the pointer's channel is taken from it afterwards.
TEST(Background, AColourFrameIsTakenSampleBySampleAndKeepsItsFormat) {
  Image frame, room;
  for (Image* im : {&frame, &room}) {
    im->width = 4;
    im->height = 3;
    im->format = PixelFormat::kRgb;
  }
  frame.bytes.resize(4 * 3 * 3);
  room.bytes.resize(4 * 3 * 3);
  for (size_t i = 0; i < frame.bytes.size(); ++i) {
    room.bytes[i] = static_cast<uint8_t>(10 + i % 3);  // the room: a little more blue
    frame.bytes[i] = static_cast<uint8_t>(50 + i);     // the pointer and the room
  }
  auto mean = AverageFrames({room.view(), room.view()});
  ASSERT_TRUE(mean.ok()) << mean.status().ToString();
  EXPECT_EQ(mean->format, PixelFormat::kRgb);
  EXPECT_EQ(mean->bytes, room.bytes);
  Image out;
  ASSERT_TRUE(SubtractBackground(frame.view(), mean->view(), &out).ok());
  EXPECT_EQ(out.format, PixelFormat::kRgb);
  ASSERT_EQ(out.bytes.size(), frame.bytes.size());
  for (size_t i = 0; i < out.bytes.size(); ++i) EXPECT_EQ(out.bytes[i], 40 + i - i % 3);
  // A mono background for a colour frame is another camera's: refused, naming both.
  const Image gray = Filled(4, 3, 8, 10);
  const Status mixed = SubtractBackground(frame.view(), gray.view(), &out);
  EXPECT_FALSE(mixed.ok());
  EXPECT_NE(mixed.message().find("RGB"), std::string::npos) << mixed.message();
}

}  // namespace
}  // namespace insitu::vision
