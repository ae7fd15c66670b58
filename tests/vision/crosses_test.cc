#include "insitu/vision/crosses.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

namespace insitu::vision {
namespace {

// A "+" of two bars (bar_px long, line_px wide) turned by angle_deg about its centre.
struct TrueCross {
  Eigen::Vector2d centre;
  double angle_deg = 0.0;
  double bar_px = 100.0;
  double line_px = 1.8;
};

// The cross blurred by a Gaussian of sigma (px), at the point (x, y): each bar is a
// rectangle, and a rectangle blurred by a round Gaussian is a product of erf differences in
// its own axes; the cross is both bars less their shared square.
double BlurredCross(const TrueCross& t, double sigma, double x, double y) {
  const double a = t.angle_deg * M_PI / 180.0, cs = std::cos(a), sn = std::sin(a);
  const double lx = cs * (x - t.centre.x()) + sn * (y - t.centre.y());
  const double ly = -sn * (x - t.centre.x()) + cs * (y - t.centre.y());
  const double k = 1.0 / (std::sqrt(2.0) * sigma);
  const auto band = [&](double s, double half) {
    return 0.5 * (std::erf((s + half) * k) - std::erf((s - half) * k));
  };
  const double l2 = 0.5 * t.bar_px, w2 = 0.5 * t.line_px;
  const double bx_l = band(lx, l2), bx_w = band(lx, w2), by_l = band(ly, l2), by_w = band(ly, w2);
  return bx_l * by_w + bx_w * by_l - bx_w * by_w;
}

// The coaxial camera's view of chrome crosses: background and line levels (gray levels of
// an 8-bit frame), the optics' blur (sigma 4.3 um on 5 um pixels: 0.86 px), then, if `noisy`,
// shot noise at 39.2 electrons per gray level (10000 e full well over 255) and 6 e read
// noise. 12-bit frames carry the same levels times 16 (rounded 16 times finer).
struct Scene {
  int width = 1024, height = 1024;
  double background = 20.0, chrome = 220.0;
  double blur_px = 0.86;
  bool noisy = false;
  bool dark_lines = false;  // lines darker than the field (levels swapped)
  int bit_depth = 8;        // 8, or 12 in 16-bit samples
  uint32_t seed = 7;
};

struct Image {
  std::vector<uint8_t> bytes;
  int width = 0, height = 0, bit_depth = 8;
  ImageView view() const {
    return {bytes.data(), width, height, static_cast<size_t>(width) * (bit_depth == 8 ? 1 : 2),
            bit_depth};
  }
};

// The image as optics and sensor make it: the cross blurred by the optics first, then
// integrated over each pixel (4 x 4 Gauss-Legendre points: the blurred cross is smooth on
// the scale of a pixel, sigma 0.86 px, so the rule is exact to ~1e-6 of the level).
Image Render(const Scene& s, const std::vector<TrueCross>& crosses) {
  std::vector<double> blurred(static_cast<size_t>(s.width) * s.height, 0.0);
  constexpr double kNodes[4] = {-0.4305681557970263, -0.1699905217924281, 0.1699905217924281,
                                0.4305681557970263};  // on [-0.5, 0.5]
  constexpr double kWeights[4] = {0.1739274225687269, 0.3260725774312731, 0.3260725774312731,
                                  0.1739274225687269};  // sum 1
  for (const TrueCross& t : crosses) {
    const double a = t.angle_deg * M_PI / 180.0, cs = std::cos(a), sn = std::sin(a);
    const double reach = 0.5 * t.bar_px + 6.0 * s.blur_px + 2.0;
    const double near = 0.5 * t.line_px + 6.0 * s.blur_px + 1.0;  // blur's reach off a bar
    for (int v = std::max(0, static_cast<int>(t.centre.y() - reach));
         v <= std::min(s.height - 1, static_cast<int>(t.centre.y() + reach)); ++v) {
      for (int u = std::max(0, static_cast<int>(t.centre.x() - reach));
           u <= std::min(s.width - 1, static_cast<int>(t.centre.x() + reach)); ++u) {
        const double lx = cs * (u - t.centre.x()) + sn * (v - t.centre.y());
        const double ly = -sn * (u - t.centre.x()) + cs * (v - t.centre.y());
        if (std::min(std::abs(lx), std::abs(ly)) > near) continue;
        double sum = 0.0;
        for (int j = 0; j < 4; ++j) {
          for (int i = 0; i < 4; ++i) {
            sum += kWeights[i] * kWeights[j] *
                   BlurredCross(t, s.blur_px, u + kNodes[i], v + kNodes[j]);
          }
        }
        blurred[static_cast<size_t>(v) * s.width + u] += sum;
      }
    }
  }
  std::mt19937 rng(s.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const double e_per_dn = 10000.0 / 255.0;
  const double lo = s.dark_lines ? s.chrome : s.background;
  const double hi = s.dark_lines ? s.background : s.chrome;
  const int scale = 1 << (s.bit_depth - 8), max_dn = (1 << s.bit_depth) - 1;
  Image img;
  img.width = s.width;
  img.height = s.height;
  img.bit_depth = s.bit_depth;
  img.bytes.resize(blurred.size() * (s.bit_depth == 8 ? 1 : 2));
  for (size_t i = 0; i < blurred.size(); ++i) {
    double dn = lo + (hi - lo) * blurred[i];
    if (s.noisy) {
      const double e = dn * e_per_dn;
      dn = (e + std::sqrt(e + 36.0) * normal(rng)) / e_per_dn;
    }
    const int q = std::clamp(static_cast<int>(std::lround(dn * scale)), 0, max_dn);
    if (s.bit_depth == 8) {
      img.bytes[i] = static_cast<uint8_t>(q);
    } else {
      img.bytes[2 * i] = static_cast<uint8_t>(q & 0xFF);
      img.bytes[2 * i + 1] = static_cast<uint8_t>(q >> 8);
    }
  }
  return img;
}

// The found cross nearest to `truth`, or nullptr.
const Cross* Nearest(const std::vector<Cross>& found, const Eigen::Vector2d& truth) {
  const Cross* best = nullptr;
  for (const Cross& c : found) {
    if (!best || (c.centre_px - truth).norm() < (best->centre_px - truth).norm()) best = &c;
  }
  return best;
}

// 25 crosses on a 200 px pitch (the reticle's 1 mm at 5 um pixels), turned as a reticle laid
// by hand and a camera mounted by hand, at sub-pixel positions.
// Crosses turned far enough to leave the 1024 px frame are left out.
std::vector<TrueCross> Grid(double angle_deg, double bar_px = 100.0) {
  std::vector<TrueCross> crosses;
  const double a = angle_deg * M_PI / 180.0;
  for (int j = -2; j <= 2; ++j) {
    for (int i = -2; i <= 2; ++i) {
      TrueCross t;
      const Eigen::Vector2d g(200.0 * i, 200.0 * j);
      t.centre = Eigen::Vector2d(511.63, 510.27) +
                 Eigen::Vector2d(std::cos(a) * g.x() - std::sin(a) * g.y(),
                                 std::sin(a) * g.x() + std::cos(a) * g.y()) +
                 Eigen::Vector2d(0.013 * (i + 3 * j), 0.029 * (j - 2 * i));  // sub-pixel phases
      t.angle_deg = angle_deg;
      t.bar_px = bar_px;
      const double reach = 0.5 * bar_px + 5.0;
      if (t.centre.minCoeff() < reach || t.centre.maxCoeff() > 1023.0 - reach) continue;
      crosses.push_back(t);
    }
  }
  return crosses;
}

// Without noise (12-bit levels, so rounding is small) the centre is exact but for what the
// method leaves: the windows (+-6 px) cut the line's image (sigma ~1 px) 6 sigma out, the
// optics' blur before the pixels leaves the sampling no alias to speak of (the blurred
// line's spectrum at 1 / px: exp(-2 pi^2 0.86^2) ~ 5e-7), and rounding to 1/16 gray is at
// worst the same all along a bar that runs with the pixel grid (0 and 45 deg): 1/16 of the
// 8-bit bound below, 0.001 px. 0.005 px bounds it at every angle.
TEST(Crosses, NoiselessCentresAreExact) {
  for (double angle : {0.0, 1.4, -7.0, 21.0, 45.0}) {
    Scene s;
    s.bit_depth = 12;
    const std::vector<TrueCross> truth = Grid(angle);
    const auto img = Render(s, truth);
    auto found = FindCrosses(img.view());
    ASSERT_TRUE(found.ok()) << found.status().ToString();
    ASSERT_EQ(found->size(), truth.size()) << "angle " << angle;
    double worst = 0.0;
    for (const TrueCross& t : truth) {
      const Cross* c = Nearest(*found, t.centre);
      ASSERT_NE(c, nullptr);
      worst = std::max(worst, (c->centre_px - t.centre).norm());
      double a = angle;
      if (a > 45.0 - 1e-9) a -= 90.0 * (c->angle_deg < 0);  // 45 deg is either bar
      EXPECT_NEAR(c->angle_deg, a, 0.01);
      EXPECT_NEAR(c->angle2_deg - c->angle_deg, 90.0, 0.01);
      EXPECT_NEAR(c->bar_px, t.bar_px, 4.0);               // the blob's extent at its threshold
      EXPECT_NEAR(c->background, s.background * 16, 1.0);  // 12-bit levels
    }
    std::printf("angle %5.1f deg: worst centre error %.5f px\n", angle, worst);
    EXPECT_LT(worst, 0.005) << "angle " << angle;
  }
}

// With the coaxial camera's noise: a centroid across a line carries ~0.025 px (the profile
// holds ~360 gray px above the background; shot noise ~2 gray at the peak and ~0.7 gray on
// the background, over a +-6 px window, the background's noise half clipped away), and each
// line rests on ~68 of them (a 100 px bar less its middle and tips), so the centre's error is
// ~0.025 / sqrt(68) = 0.003 px per coordinate. Over 25 crosses the rms must stay under
// 0.01 px and the worst under 0.03 px (~3 sigma of 50 coordinates, times 3 for the estimate);
// in micrometres at 5 um pixels: 0.05 and 0.15 um, far below seed 001's 3 um.
TEST(Crosses, NoisyCentresToAFewThousandthsOfAPixel) {
  Scene s;
  s.noisy = true;
  const std::vector<TrueCross> truth = Grid(1.4);
  const auto img = Render(s, truth);
  auto found = FindCrosses(img.view());
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  ASSERT_EQ(found->size(), truth.size());
  double sum2 = 0.0, worst = 0.0, residual = 0.0;
  for (const TrueCross& t : truth) {
    const Cross* c = Nearest(*found, t.centre);
    const double e = (c->centre_px - t.centre).norm();
    sum2 += e * e;
    worst = std::max(worst, e);
    residual += c->residual_px / truth.size();
    EXPECT_GT(c->samples, 120);
    EXPECT_NEAR(c->contrast, 141.0, 15.0);  // 200 gray x erf(0.9 / (0.86 sqrt 2)) = 141
  }
  const double rms = std::sqrt(sum2 / truth.size());
  std::printf("noisy: rms %.4f px, worst %.4f px, line residual %.4f px\n", rms, worst, residual);
  EXPECT_LT(rms, 0.01);
  EXPECT_LT(worst, 0.03);
  // The samples scatter about their lines by the per-centroid noise (~0.025 px): a check
  // that the noise is there and the estimate above is of the right size.
  EXPECT_GT(residual, 0.01);
  EXPECT_LT(residual, 0.06);
}

// Dark lines on a bright field (a negative reticle, or back light) with bright = false.
TEST(Crosses, DarkLinesWhenAsked) {
  Scene s;
  s.noisy = true;
  s.dark_lines = true;
  const std::vector<TrueCross> truth = Grid(-3.0);
  const auto img = Render(s, truth);
  CrossOptions o;
  o.bright = false;
  auto found = FindCrosses(img.view(), o);
  ASSERT_TRUE(found.ok());
  ASSERT_EQ(found->size(), truth.size());
  for (const TrueCross& t : truth) {
    EXPECT_LT((Nearest(*found, t.centre)->centre_px - t.centre).norm(), 0.03);
  }
  EXPECT_NEAR(found->front().background, s.chrome, 2.0);
  // Bright lines asked for on this image: the bright field has none.
  auto bright = FindCrosses(img.view());
  ASSERT_TRUE(bright.ok());
  EXPECT_TRUE(bright->empty());
}

// Only whole crosses: one cut by the image edge, a disc, a single line and crosses of the
// wrong size are not reported.
TEST(Crosses, OnlyWholeCrossesOfTheAskedSize) {
  Scene s;
  s.noisy = true;
  std::vector<TrueCross> truth = {{{300.5, 300.2}, 2.0}, {{1000.0, 500.0}, 2.0}};
  auto img = Render(s, truth);
  // A disc of radius 20 px and a lone bar, drawn into the image.
  for (int v = 0; v < s.height; ++v) {
    for (int u = 0; u < s.width; ++u) {
      const bool disc = std::hypot(u - 700.0, v - 300.0) < 20.0;
      const bool bar = std::abs(v - 700.0) < 1.0 && std::abs(u - 300.0) < 50.0;
      if (disc || bar) img.bytes[static_cast<size_t>(v) * s.width + u] = 200;
    }
  }
  auto found = FindCrosses(img.view());
  ASSERT_TRUE(found.ok());
  ASSERT_EQ(found->size(), 1u);
  EXPECT_LT((found->front().centre_px - truth[0].centre).norm(), 0.03);
  CrossOptions small;
  small.max_bar_px = 60.0;  // the 100 px cross is too long
  found = FindCrosses(img.view(), small);
  ASSERT_TRUE(found.ok());
  EXPECT_TRUE(found->empty());
}

// 8-bit frames without noise: rounding to whole gray levels is the same all along a bar that
// runs with the pixel grid, so it does not average out there. A centroid moves by at most
// 0.5 gray x sum |d| over the ~7 px (d = -3..3) the line's image covers, over the profile's
// ~360 gray px: 6 / 360 = 0.017 px; bound 0.02 px. A bar turned by a degree or more sees the
// rounding in every phase along it: 0.005 px. (With the camera's noise, ~0.7 gray and more,
// the rounding is dithered away: the noisy test.)
TEST(Crosses, EightBitRounding) {
  for (double angle : {0.0, 1.4, 21.0, 45.0}) {
    Scene s;
    const std::vector<TrueCross> truth = Grid(angle);
    const Image img = Render(s, truth);
    auto found = FindCrosses(img.view());
    ASSERT_TRUE(found.ok());
    ASSERT_EQ(found->size(), truth.size());
    double worst = 0.0;
    for (const TrueCross& t : truth) {
      worst = std::max(worst, (Nearest(*found, t.centre)->centre_px - t.centre).norm());
    }
    std::printf("8-bit angle %5.1f deg: worst centre error %.5f px\n", angle, worst);
    EXPECT_LT(worst, angle == 0.0 || angle == 45.0 ? 0.02 : 0.005) << "angle " << angle;
  }
}

TEST(Crosses, BadInputIsRefusedByName) {
  CrossOptions o;
  o.max_line_width_px = 0.0;
  EXPECT_NE(o.Validate().message().find("max_line_width_px"), std::string::npos);
  o = CrossOptions{};
  o.min_bar_px = 10.0;  // not longer than two line widths
  EXPECT_NE(o.Validate().message().find("min_bar_px"), std::string::npos);
  o = CrossOptions{};
  o.min_contrast_fraction = 0.0;
  EXPECT_NE(o.Validate().message().find("min_contrast_fraction"), std::string::npos);
  o = CrossOptions{};
  o.border_px = -1;
  EXPECT_NE(o.Validate().message().find("border_px"), std::string::npos);
  auto empty = FindCrosses(ImageView{});
  EXPECT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::vision
