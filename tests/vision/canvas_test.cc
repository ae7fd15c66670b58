#include "insitu/vision/canvas.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

namespace insitu::vision {
namespace {

namespace fs = std::filesystem;

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "insitu_canvas_test";
  fs::create_directories(dir);
  return dir / name;
}

// The pixel (x, y) of a written PNG as 0xRRGGBB.
int PixelAt(const fs::path& png, int x, int y) {
  const cv::Mat m = cv::imread(png.string(), cv::IMREAD_COLOR);
  EXPECT_FALSE(m.empty()) << png;
  if (m.empty()) return -1;
  const cv::Vec3b bgr = m.at<cv::Vec3b>(y, x);
  return bgr[2] << 16 | bgr[1] << 8 | bgr[0];
}

TEST(Canvas, ColoursAreRgbAndRegionsClipTheirDrawing) {
  Canvas c(40, 30);  // white
  c.Rectangle(2, 3, 5, 4, {.rgb = 0x123456, .thickness = kFill});
  // A region's line runs from its corner across it and is cut at its edge.
  Canvas region = c.Region(20, 10, 10, 10);
  region.Line({0, 5}, {100, 5}, {.rgb = 0xFF0000});
  const fs::path png = Scratch("colours.png");
  ASSERT_TRUE(c.WritePng(png.string()).ok());
  EXPECT_EQ(PixelAt(png, 2, 3), 0x123456);
  EXPECT_EQ(PixelAt(png, 6, 6), 0x123456);  // [x, x + width): the last pixel is x + 4
  EXPECT_EQ(PixelAt(png, 7, 6), 0xFFFFFF);
  EXPECT_EQ(PixelAt(png, 20, 15), 0xFF0000);
  EXPECT_EQ(PixelAt(png, 29, 15), 0xFF0000);
  EXPECT_EQ(PixelAt(png, 30, 15), 0xFFFFFF);  // outside the region
}

TEST(Canvas, FromGrayScalesDeepSamplesAndResizes) {
  // A 12-bit frame at full scale and at zero: 255 and 0 once scaled by 255 / 4095.
  const std::vector<uint16_t> samples{4095, 0, 0, 4095};
  const ImageView view{samples.data(), 2, 2, 4, 12};
  auto c = Canvas::FromGray(view, 2.0);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->width(), 4);
  EXPECT_EQ(c->height(), 4);
  c->Resize(0.5);
  EXPECT_EQ(c->width(), 2);
  EXPECT_FALSE(Canvas::FromGray(ImageView{}).ok());
}

TEST(Canvas, RgbOfRoundsAndClamps) {
  EXPECT_EQ(RgbOf(255.0, 127.6, -3.0), 0xFF8000);
  EXPECT_EQ(RgbOf(300.0, 0.4, 1.5), 0xFF0002);
}

TEST(Canvas, FailuresAreStatusesNamingTheFile) {
  Canvas c(10, 10);
  const std::string nowhere = "/nonexistent-dir/insitu/figure.png";
  const Status unwritable = c.WritePng(nowhere);
  EXPECT_EQ(unwritable.code(), StatusCode::kDeviceError);
  EXPECT_NE(unwritable.message().find(nowhere), std::string::npos) << unwritable.message();
  // A drawing OpenCV refuses (a region reaching outside the canvas) is kept for WritePng.
  Canvas outside = c.Region(5, 5, 20, 20);
  outside.Line({0, 0}, {3, 3}, {});
  const std::string path = Scratch("refused.png").string();
  const Status refused = c.WritePng(path);
  EXPECT_EQ(refused.code(), StatusCode::kDeviceError);
  EXPECT_NE(refused.message().find(path), std::string::npos) << refused.message();
  // An unknown extension: OpenCV throws, the adapter answers.
  EXPECT_EQ(Canvas(4, 4).WritePng(Scratch("figure.nosuchformat").string()).code(),
            StatusCode::kDeviceError);
}

}  // namespace
}  // namespace insitu::vision
