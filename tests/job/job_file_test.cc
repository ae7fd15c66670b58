// Loading job files: `--set world=FILE` replaces the job's world file before it is read (it
// once set a key nobody read, so the job silently ran on its own world), and `--set world.*`
// keys still apply on top of whichever world file is used.
#include "insitu/job/job_file.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace insitu::job {
namespace {

namespace fs = std::filesystem;

TEST(JobFile, SetWorldReplacesTheWorldFileBeforeItIsRead) {
  const fs::path dir = fs::temp_directory_path() / "insitu_job_file_test";
  fs::create_directories(dir);
  std::ofstream(dir / "a.yaml") << "name: a\nseed: 1\n";
  std::ofstream(dir / "b.yaml") << "name: b\nseed: 2\n";
  const std::string text = "job: scan\nworld: a.yaml\n";
  auto plain = LoadJobText(text, "t.yaml", dir.string(), {});
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_EQ(*plain->world.Child("name").AsString(), "a");
  auto other = LoadJobText(text, "t.yaml", dir.string(), {"world.seed=7", "world=b.yaml"});
  ASSERT_TRUE(other.ok()) << other.status().ToString();
  EXPECT_EQ(*other->world.Child("name").AsString(), "b");
  EXPECT_EQ(*other->world.Child("seed").AsString(), "7");
  // A world file on a base: the base's keys, the file's on top.
  std::ofstream(dir / "c.yaml") << "base: a.yaml\nname: c\n";
  auto based = LoadJobText(text, "t.yaml", dir.string(), {"world=c.yaml"});
  ASSERT_TRUE(based.ok()) << based.status().ToString();
  EXPECT_EQ(*based->world.Child("name").AsString(), "c");
  EXPECT_EQ(*based->world.Child("seed").AsString(), "1");
  auto missing = LoadJobText(text, "t.yaml", dir.string(), {"world=nope.yaml"});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("nope.yaml"), std::string::npos);
}

}  // namespace
}  // namespace insitu::job
