// Raster patterns: image to mask, hatch lines at a spacing and angle, placement
// on the part.
#include "insitu/pattern/raster.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

namespace insitu::pattern {
namespace {

namespace fs = std::filesystem;

Mask Full(int w, int h) {
  Mask m;
  m.width = w;
  m.height = h;
  m.on.assign(static_cast<size_t>(w) * h, 1);
  return m;
}

TEST(Raster, ImageToMaskAndBadImages) {
  const fs::path dir = fs::temp_directory_path() / "insitu_raster_test";
  fs::create_directories(dir);
  cv::Mat img(60, 100, CV_8UC1, cv::Scalar(255));
  img(cv::Rect(10, 5, 40, 20)).setTo(0);
  ASSERT_TRUE(cv::imwrite((dir / "rect.png").string(), img));
  auto m = LoadRasterMask((dir / "rect.png").string());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(std::count(m->on.begin(), m->on.end(), 1), 800);
  EXPECT_TRUE(m->at(10, 5));
  EXPECT_FALSE(m->at(9, 5));
  auto inv = LoadRasterMask((dir / "rect.png").string(), 128, true);
  ASSERT_TRUE(inv.ok());
  EXPECT_EQ(std::count(inv->on.begin(), inv->on.end(), 1), 6000 - 800);

  EXPECT_EQ(LoadRasterMask((dir / "missing.png").string()).status().code(), StatusCode::kNotFound);
  std::ofstream(dir / "text.png") << "not an image";
  EXPECT_EQ(LoadRasterMask((dir / "text.png").string()).status().code(),
            StatusCode::kInvalidArgument);
  cv::Mat white(10, 10, CV_8UC1, cv::Scalar(255));
  ASSERT_TRUE(cv::imwrite((dir / "white.png").string(), white));
  const auto none = LoadRasterMask((dir / "white.png").string());
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("no pixel to mark"), std::string::npos);
}

TEST(Raster, DitheredGreyKeepsItsDensity) {
  const fs::path dir = fs::temp_directory_path() / "insitu_raster_test";
  fs::create_directories(dir);
  // A grey ramp: column band b (20 px wide) at grey 255 * b / 10, 200 rows.
  cv::Mat img(200, 220, CV_8UC1);
  for (int u = 0; u < img.cols; ++u) img.col(u).setTo(std::min(255, 255 * (u / 20) / 10));
  ASSERT_TRUE(cv::imwrite((dir / "ramp.png").string(), img));
  auto m = LoadRasterMask((dir / "ramp.png").string(), 128, false, true);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  for (int b = 0; b <= 10; ++b) {
    int on = 0;
    for (int v = 0; v < 200; ++v) {
      for (int u = 20 * b + 2; u < 20 * b + 18; ++u) on += m->at(u, v);  // away from band edges
    }
    // Error diffusion keeps the mean ink: the marked fraction of a band is its
    // ink to within the error carried across the band's edges and rows (at most
    // one pixel's worth per row: 1/16 of 3200 pixels).
    const double ink = 1.0 - std::min(255, 255 * b / 10) / 255.0;
    EXPECT_NEAR(on / 3200.0, ink, 1.0 / 16.0) << "band " << b;
  }
}

// A 1 mm square (100 px of 10 um) hatched every 40 um: the lines through |k *
// 0.04| < 0.5 mm, i.e. k = -12..12, each 1 mm long to within the quarter-pixel
// sampling (ends within 1/8 px = 1.25 um).
TEST(Raster, HatchLinesFillTheSquareAtTheSpacing) {
  const Mask m = Full(100, 100);
  for (double angle : {0.0, 90.0}) {
    auto lines = HatchMask(m, 0.01, 0.04, angle);
    ASSERT_TRUE(lines.ok());
    ASSERT_EQ(lines->size(), 25u) << angle;
    for (const Segment2& s : *lines) EXPECT_NEAR((s.b - s.a).norm(), 1.0, 0.0026) << angle;
    // Neighbouring lines 40 um apart, running in opposite directions.
    const Segment2& l0 = (*lines)[0];
    const Segment2& l1 = (*lines)[1];
    const Eigen::Vector2d d = (l0.b - l0.a).normalized();
    const Eigen::Vector2d n(-d.y(), d.x());
    EXPECT_NEAR(std::abs(n.dot(l1.a - l0.a)), 0.04, 1e-9);
    EXPECT_LT((l1.b - l1.a).dot(l0.b - l0.a), 0.0);
  }
  // At 45 degrees the hatch length is still area / spacing (25 mm), up to the
  // ends.
  auto diag = HatchMask(m, 0.01, 0.04, 45.0);
  ASSERT_TRUE(diag.ok());
  double total = 0;
  for (const Segment2& s : *diag) total += (s.b - s.a).norm();
  EXPECT_NEAR(total, 25.0, 0.1);
  EXPECT_FALSE(HatchMask(m, 0.01, 0.0, 0.0).ok());
  EXPECT_FALSE(HatchMask(m, -1.0, 0.04, 0.0).ok());
}

TEST(Raster, PlacementScalesRotatesThenMoves) {
  Placement p;
  p.scale = 2.0;
  p.rotation_deg = 90.0;
  p.offset_mm = {5.0, 0.0};
  const Eigen::Vector2d q = p.Apply({1.0, 0.0});
  EXPECT_NEAR(q.x(), 5.0, 1e-12);
  EXPECT_NEAR(q.y(), 2.0, 1e-12);
  const auto placed = Place({{{0, 0}, {1, 0}}}, p);
  ASSERT_EQ(placed.size(), 1u);
  EXPECT_NEAR((placed[0].b - placed[0].a).norm(), 2.0, 1e-12);
}

}  // namespace
}  // namespace insitu::pattern

namespace insitu::pattern {
namespace {

// Only the image formats patterns come in reach OpenCV's decoders: a DICOM file (OpenCV
// would hand it to GDCM, which aborts the process on a malformed one), or text, is refused
// by its first bytes, naming the file.
TEST(RasterBytes, OnlyPatternImageFormatsAreDecoded) {
  const std::string dicom = std::string(128, '\0') + "DICM" + std::string(64, '\x01');
  auto refused = DecodeRasterMask(dicom, "scan.dcm");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("scan.dcm"), std::string::npos);
  EXPECT_FALSE(DecodeRasterMask("P5 not really", "x.pgm").ok());  // PNM magic, bad body
  // A 2 x 1 PGM (binary): one black pixel (marked), one white.
  const std::string pgm = std::string("P5\n2 1\n255\n") + '\0' + '\xff';
  auto mask = DecodeRasterMask(pgm, "two.pgm");
  ASSERT_TRUE(mask.ok()) << mask.status().ToString();
  EXPECT_EQ(mask->width, 2);
  EXPECT_TRUE(mask->at(0, 0));
  EXPECT_FALSE(mask->at(1, 0));
}

}  // namespace
}  // namespace insitu::pattern
