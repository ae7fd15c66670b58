// What a daemon client may name: job files inside the jobs folder only, and no `set` that
// redirects a file.
#include "insitu/daemon/confine.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

namespace insitu::daemon {
namespace {

namespace fs = std::filesystem;

TEST(Confine, JobPathsStayInTheJobsFolder) {
  const fs::path dir =
      fs::temp_directory_path() / ("insitu_confine_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "jobs" / "sub");
  std::ofstream(dir / "jobs" / "sub" / "scan.yaml") << "job: scan\n";
  std::ofstream(dir / "secret.yaml") << "token: x\n";
  const std::string jobs = (dir / "jobs").string();

  auto ok = JobPathInside(jobs, "sub/scan.yaml");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(fs::path(*ok), fs::weakly_canonical(dir / "jobs" / "sub" / "scan.yaml"));

  for (const std::string& bad : {(dir / "secret.yaml").string(), std::string("../secret.yaml"),
                                std::string("sub/../../secret.yaml"), std::string("")}) {
    auto r = JobPathInside(jobs, bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.status().message().find("token"), std::string::npos);  // never the contents
  }
  // A link inside the folder pointing out of it.
  fs::create_symlink(dir / "secret.yaml", dir / "jobs" / "link.yaml");
  EXPECT_FALSE(JobPathInside(jobs, "link.yaml").ok());
}

TEST(Confine, SetNeverRedirectsAFile) {
  EXPECT_TRUE(CheckSetKeys({"scan.line_spacing_mm=0.5", "world.part.position_mm=[1,2]",
                            "camera.exposure_ms=20", "profiler.mount=[0,0,0,0,0,0]"})
                  .ok());
  // Negative numbers and lists of numbers are values, not sections.
  EXPECT_TRUE(CheckSetKeys({"scan.x_start_mm=-3.0", "world.part.position_mm=[-1.5,2]"}).ok());
  for (const char* bad :
       {"diagnosis={\"baseline\":\"/any\",\"record_baseline\":true}",
        "diagnosis.record_baseline=true", "job=calibrate", "head={correction: /etc/t.csv}",
        "items=[{\"pattern\": {\"file\": \"/etc/x\"}}]", "profiler=- mount_file: /x",
        "output.calibration=/etc/x", "machine.calibration=/tmp/c.yaml", "design.file=/etc/passwd",
        "profiler.mount_file=/tmp/m.yaml", "head.correction=/tmp/t.csv", "world=/tmp/w.yaml",
        "output=/tmp", "diagnosis.baseline=/tmp/b.csv", "head.model_extension=/tmp/e.yaml",
        "diagnosis=record_baseline:\ttrue", "head=[[1], {a: 2}]"}) {
    const Status s = CheckSetKeys({bad});
    EXPECT_FALSE(s.ok()) << bad;
    EXPECT_NE(s.message().find("set: '"), std::string::npos) << s.message();
  }
}

// An inline job by the same rules, at any depth.
TEST(Confine, AnInlineJobNamesNoFileOutsideAndNoOutput) {
  const std::string jobs = INSITU_SOURCE_DIR;
  EXPECT_TRUE(CheckInlineJob(nlohmann::json::parse(R"({"job": "scan", "world": "config/worlds/default.yaml",
      "machine": {"calibration": "calib/as_designed.yaml"}})"), jobs).ok());
  for (const char* bad :
       {R"({"job": "calibrate", "output": {"calibration": "/var/lib/insitu/x"}})",
        R"({"job": "diagnose_machine", "diagnosis": {"record_baseline": true}})",
        R"({"job": "scan", "world": "/etc/insitu/w.yaml"})",
        R"({"job": "mark", "items": [{"pattern": {"kind": "svg", "file": "../../etc/x.svg"}}]})"}) {
    const Status s = CheckInlineJob(nlohmann::json::parse(bad), jobs);
    EXPECT_FALSE(s.ok()) << bad;
  }
}

// Files a job names lie inside the read roots (or are the cell's own files); what it writes
// (output) is not a read. The error names the key and its line, never a file's contents.
TEST(Confine, WhatAJobReadsStaysInsideTheRoots) {
  const fs::path dir =
      fs::temp_directory_path() / ("insitu_confine_reads_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "jobs");
  fs::create_directories(dir / "shared");
  std::ofstream(dir / "cell.yaml") << "the cell's calibration\n";
  ReadRoots roots;
  roots.folders = {(dir / "jobs").string(), (dir / "shared").string()};
  roots.files = {(dir / "cell.yaml").string()};
  EXPECT_TRUE(InsideRoots((dir / "shared" / "a.svg").string(), roots));
  EXPECT_TRUE(InsideRoots((dir / "cell.yaml").string(), roots));
  EXPECT_FALSE(InsideRoots((dir / "other.yaml").string(), roots));
  EXPECT_FALSE(InsideRoots((dir / "jobs" / ".." / "other.yaml").string(), roots));
  const auto doc = ConfigNode::Parse(
      "job: mark\n"
      "machine:\n"
      "  calibration: ../cell.yaml\n"
      "pattern:\n"
      "  file: ../shared/plate.svg\n"
      "output:\n"
      "  calibration: /anywhere/x.yaml\n",
      (dir / "jobs" / "job.yaml").string());
  ASSERT_TRUE(doc.ok());
  EXPECT_TRUE(CheckReads(*doc, (dir / "jobs").string(), roots).ok());
  auto outside = ConfigNode::Parse("pattern:\n  file: /etc/hostname\n", "job.yaml");
  ASSERT_TRUE(outside.ok());
  const Status refused = CheckReads(*outside, (dir / "jobs").string(), roots);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("job.yaml:2"), std::string::npos) << refused.message();
  EXPECT_NE(refused.message().find("read_roots"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace insitu::daemon
