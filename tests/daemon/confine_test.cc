// What a daemon client may name: job files inside the jobs folder only, and no `set` that
// redirects a file.
#include "insitu/daemon/confine.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace insitu::daemon {
namespace {

namespace fs = std::filesystem;

TEST(Confine, JobPathsStayInTheJobsFolder) {
  const fs::path dir = fs::temp_directory_path() / "insitu_confine_test";
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
  for (const char* bad :
       {"output.calibration=/etc/x", "machine.calibration=/tmp/c.yaml", "design.file=/etc/passwd",
        "profiler.mount_file=/tmp/m.yaml", "head.correction=/tmp/t.csv", "world=/tmp/w.yaml",
        "output=/tmp", "diagnosis.baseline=/tmp/b.csv", "head.model_extension=/tmp/e.yaml"}) {
    const Status s = CheckSetKeys({bad});
    EXPECT_FALSE(s.ok()) << bad;
    EXPECT_NE(s.message().find("names a file"), std::string::npos) << s.message();
  }
}

}  // namespace
}  // namespace insitu::daemon
