#include "insitu/geometry/cloud.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace insitu::geometry {
namespace {

TEST(Cloud, WritesABinaryPlyWithEveryPoint) {
  Cloud cloud;
  for (int i = 0; i < 100; ++i) {
    CloudPoint p;
    p.point_in_galvo = Eigen::Vector3f(i * 0.1f, -i * 0.2f, 3.0f);
    p.intensity = static_cast<float>(i);
    cloud.push_back(p);
  }
  const std::string path = (std::filesystem::temp_directory_path() / "cloud_test.ply").string();
  ASSERT_TRUE(SaveCloudPly(cloud, path).ok());
  std::ifstream f(path, std::ios::binary);
  std::string header, line;
  while (std::getline(f, line) && line != "end_header") header += line + "\n";
  EXPECT_NE(header.find("element vertex 100"), std::string::npos) << header;
  EXPECT_NE(header.find("binary_little_endian"), std::string::npos);
}

TEST(Cloud, RefusesEmptyCloudAndUnwritablePath) {
  EXPECT_FALSE(SaveCloudPly({}, "/tmp/empty.ply").ok());
  Cloud one(1);
  EXPECT_FALSE(SaveCloudPly(one, "/nonexistent/dir/cloud.ply").ok());
}

}  // namespace
}  // namespace insitu::geometry
