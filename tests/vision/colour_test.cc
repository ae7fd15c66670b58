// Colour frames: the laser's channel out of a Bayer mosaic or an RGB buffer, and the finders'
// refusal of a colour frame given as if it were mono.
#include "insitu/vision/colour.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "insitu/vision/stripe.h"
#include "insitu/vision/targets.h"

namespace insitu::vision {
namespace {

constexpr std::array<PixelFormat, 4> kBayers = {PixelFormat::kBayerRG, PixelFormat::kBayerGR,
                                                PixelFormat::kBayerGB, PixelFormat::kBayerBG};

// The mosaics as GenICam's PFNC draws them: the first two rows' filters.
int Filter(PixelFormat f, int u, int v) {
  const char* rows[2] = {"", ""};
  switch (f) {
    case PixelFormat::kBayerRG:
      rows[0] = "RG", rows[1] = "GB";
      break;
    case PixelFormat::kBayerGR:
      rows[0] = "GR", rows[1] = "BG";
      break;
    case PixelFormat::kBayerGB:
      rows[0] = "GB", rows[1] = "RG";
      break;
    default:
      rows[0] = "BG", rows[1] = "GR";
      break;
  }
  const char c = rows[v & 1][u & 1];
  return c == 'R' ? 0 : c == 'G' ? 1 : 2;
}

uint8_t Q(double g) { return static_cast<uint8_t>(std::lround(std::clamp(g, 0.0, 255.0))); }

// A scene as three planes (red, green, blue gray levels per pixel), made into a mosaic or an
// interleaved buffer as a camera delivers it.
struct Scene {
  int w, h;
  std::function<std::array<double, 3>(int, int)> rgb;

  std::vector<uint8_t> Mosaic(PixelFormat f) const {
    std::vector<uint8_t> b(static_cast<size_t>(w) * h);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) b[static_cast<size_t>(v) * w + u] = Q(rgb(u, v)[Filter(f, u, v)]);
    }
    return b;
  }
  std::vector<uint8_t> Interleaved(bool bgr) const {
    std::vector<uint8_t> b(static_cast<size_t>(w) * h * 3);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        for (int k = 0; k < 3; ++k) {
          b[(static_cast<size_t>(v) * w + u) * 3 + k] = Q(rgb(u, v)[bgr ? 2 - k : k]);
        }
      }
    }
    return b;
  }
};

TEST(Colour, TheLaserChannelFollowsItsWavelength) {
  EXPECT_EQ(*ChannelOfWavelength(650.0), ColourChannel::kRed);
  EXPECT_EQ(*ChannelOfWavelength(635.0), ColourChannel::kRed);
  EXPECT_EQ(*ChannelOfWavelength(532.0), ColourChannel::kGreen);
  EXPECT_EQ(*ChannelOfWavelength(405.0), ColourChannel::kBlue);
  EXPECT_FALSE(ChannelOfWavelength(10600.0).ok());
}

// Interleaved samples: each channel is its own byte of the pixel, in the format's order.
TEST(Colour, AnRgbOrBgrFrameGivesItsChannel) {
  const Scene scene{7, 5, [](int u, int v) {
                      return std::array<double, 3>{10.0 + u, 100.0 + v, 200.0 + u + v};
                    }};
  for (bool bgr : {false, true}) {
    const std::vector<uint8_t> buffer = scene.Interleaved(bgr);
    const ImageView view{buffer.data(), 7, 5, 21, 8, bgr ? PixelFormat::kBgr : PixelFormat::kRgb};
    for (int k = 0; k < 3; ++k) {
      Image out;
      ASSERT_TRUE(ReduceToChannel(view, static_cast<ColourChannel>(k), &out).ok());
      for (int v = 0; v < 5; ++v) {
        for (int u = 0; u < 7; ++u) {
          EXPECT_EQ(out.bytes[static_cast<size_t>(v) * 7 + u], Q(scene.rgb(u, v)[k]));
        }
      }
    }
  }
}

// Bilinear demosaicking of one channel is exact on a plane that is linear in u and v (each
// missing sample is the mean of two or four symmetric neighbours): every mosaic, every
// channel, inside the border. A crop at odd offsets is the same mosaic seen from elsewhere
// (ImageView::Crop shifts its format): its reduction is the reduction's crop.
TEST(Colour, EachMosaicGivesEachChannelWhereTheSensorSawIt) {
  const Scene scene{16, 12, [](int u, int v) {
                      return std::array<double, 3>{20.0 + 3 * u + 2 * v, 60.0 + 2 * u + 5 * v,
                                                   100.0 + 4 * u + 3 * v};
                    }};
  for (PixelFormat f : kBayers) {
    const std::vector<uint8_t> mosaic = scene.Mosaic(f);
    const ImageView view{mosaic.data(), 16, 12, 16, 8, f};
    for (int k = 0; k < 3; ++k) {
      Image full;
      ASSERT_TRUE(ReduceToChannel(view, static_cast<ColourChannel>(k), &full).ok());
      for (int v = 1; v < 11; ++v) {
        for (int u = 1; u < 15; ++u) {
          EXPECT_EQ(full.bytes[static_cast<size_t>(v) * 16 + u], Q(scene.rgb(u, v)[k]))
              << PixelFormatName(f) << " channel " << k << " at " << u << ", " << v;
        }
      }
      Image crop;
      ASSERT_TRUE(
          ReduceToChannel(view.Crop(3, 5, 9, 6), static_cast<ColourChannel>(k), &crop).ok());
      for (int v = 1; v < 5; ++v) {
        for (int u = 1; u < 8; ++u) {
          EXPECT_EQ(crop.bytes[static_cast<size_t>(v) * 9 + u],
                    full.bytes[static_cast<size_t>(v + 5) * 16 + u + 3])
              << PixelFormatName(f) << " channel " << k;
        }
      }
    }
  }
}

// The pointer's red line (650 nm: through the red filters at 0.9 of its peak, the green at 0.1,
// the blue at 0.05) under white room light, on a BayerRG sensor. Its red plane holds the stripe
// sampled every second row (a red column) or interpolated from two such columns; the run above
// K then holds two or three red samples, and the centroid of g - K over them is off the
// line's centre by a bias that depends on where the line crosses the 2 px lattice: the line
// climbs 0.04 px a column, so the 62 columns sweep every phase. That bias measures up to 0.12 px
// here (the background windows beside the run also read interpolated samples; the same optics
// on a mono sensor: 0.015 px), so 0.15 px is allowed; a mosaic read as gray would scatter by
// the filters' 0.9 : 0.1 ratio, rows apart.
TEST(Colour, APointerLineOnABayerSensorIsFoundInItsRedPlane) {
  constexpr double kSigma = 1.5, kPeak = 180.0, kRoom = 30.0;
  const auto centre = [](int u) { return 20.3 + 0.04 * u; };
  const Scene scene{
      64, 48, [&](int u, int v) {
        const double d = v - centre(u);
        const double line = kPeak * std::exp(-d * d / (2 * kSigma * kSigma));
        return std::array<double, 3>{kRoom + 0.9 * line, kRoom + 0.1 * line, kRoom + 0.05 * line};
      }};
  const std::vector<uint8_t> mosaic = scene.Mosaic(PixelFormat::kBayerRG);
  const ImageView view{mosaic.data(), 64, 48, 64, 8, PixelFormat::kBayerRG};
  StripeOptions options;
  options.direction = StripeDirection::kColumns;
  options.threshold_ratio = 0.5;
  options.median_kernel = 1;
  StripeExtractor extractor(options);
  StripeResult result;
  // Given as it is, the mosaic is refused by name, not read as gray.
  const Status refused = extractor.Extract(view, &result);
  EXPECT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("BayerRG"), std::string::npos) << refused.message();
  Image red;
  ASSERT_TRUE(ReduceToChannel(view, ColourChannel::kRed, &red).ok());
  ASSERT_TRUE(extractor.Extract(red.view(), &result).ok());
  int valid = 0;
  for (int u = 1; u < 63; ++u) {
    if (result.status[u] != StripeStatus::kValid) continue;
    ++valid;
    EXPECT_NEAR(result.center[u], centre(u), 0.15) << "column " << u;
  }
  EXPECT_EQ(valid, 62);
}

// Every finder reading gray refuses a colour view by its format's name.
TEST(Colour, TheFindersRefuseAColourFrameByName) {
  std::vector<uint8_t> rgb(30 * 20 * 3, 50);
  const ImageView view{rgb.data(), 30, 20, 90, 8, PixelFormat::kRgb};
  auto spot = FindSpot(view, view, {});
  ASSERT_FALSE(spot.ok());
  EXPECT_NE(spot.status().message().find("RGB"), std::string::npos) << spot.status().message();
  auto board = FindChessboard(view, {});
  ASSERT_FALSE(board.ok());
  EXPECT_NE(board.status().message().find("RGB"), std::string::npos);
}

}  // namespace
}  // namespace insitu::vision
