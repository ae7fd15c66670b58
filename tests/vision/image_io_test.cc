#include "insitu/vision/image_io.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <vector>

namespace insitu::vision {
namespace {

namespace fs = std::filesystem;

TEST(ImageIo, WritesAFramesSamplesAsGrayPng) {
  Frame f;
  f.width = 3;
  f.height = 2;
  f.bytes = {0, 10, 20, 30, 40, 255};
  const fs::path dir = fs::temp_directory_path() / "insitu_image_io_test";
  fs::create_directories(dir);
  const std::string path = (dir / "frame.png").string();
  ASSERT_TRUE(WritePng(path, ViewOf(f)).ok());
  const cv::Mat back = cv::imread(path, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.type(), CV_8UC1);
  ASSERT_EQ(back.cols, 3);
  EXPECT_EQ(back.at<uint8_t>(1, 0), 30);
  EXPECT_EQ(back.at<uint8_t>(1, 2), 255);

  // A crop keeps the frame's stride.
  ASSERT_TRUE(WritePng(path, ViewOf(f).Crop(1, 1, 2, 1)).ok());
  const cv::Mat crop = cv::imread(path, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(crop.cols, 2);
  EXPECT_EQ(crop.at<uint8_t>(0, 0), 40);
}

TEST(ImageIo, FailuresAreStatuses) {
  EXPECT_EQ(WritePng("x.png", ImageView{}).code(), StatusCode::kInvalidArgument);
  const std::vector<uint8_t> px(4, 0);
  const Status s = WritePng("/nonexistent-dir/insitu/x.png", {px.data(), 2, 2, 2, 8});
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_NE(s.message().find("/nonexistent-dir/insitu/x.png"), std::string::npos);
}

}  // namespace
}  // namespace insitu::vision
