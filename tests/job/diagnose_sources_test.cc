// insitu diagnose reads field tables from any source (job/diagnose_job.h, LoadDiagnoseData): an
// EzCad .cor file generated from a simulated head driven linearly (the simulator's optics with
// f-theta distortion, tilted axes, zero offsets and gain errors), stored in the documented
// convention of a board whose second word drives the first mirror; the same table as a
// correction CSV; and measured field data. The .cor is read the way the head explains it, and
// the diagnosis names the physical head first and explains >= 95 % of the held-out error.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "insitu/hw/lmc_cor.h"
#include "insitu/job/cor_reading.h"
#include "insitu/job/diagnose_job.h"
#include "insitu/optics/scan_head.h"

namespace insitu::job {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector2d;

// The correction a linearly driven head needs at (x, y): the command whose spot lands there,
// minus (x, y). f = 160 mm behind a 110 mm lens field.
Vector2d Needed(double x, double y) {
  optics::HeadGeometry g;
  g.focal_length_mm = 160.0;
  g.ftheta_c3 = 0.04;
  g.ftheta_c5 = -0.1;
  g.x_axis_tilt_mrad = 1.5;
  g.y_axis_tilt_mrad = -0.8;
  const optics::ScanOptics optics(g);
  optics::MirrorAngles a;
  EXPECT_TRUE(optics.Solve(x, y, 0.0, &a));
  const double gain_x = 1.004, gain_y = 0.997, x0 = 0.6e-3, y0 = -0.4e-3;
  return Vector2d((a.x_rad - x0) * g.focal_length_mm / gain_x - x,
                  (a.y_rad - y0) * g.focal_length_mm / gain_y - y);
}

TEST(DiagnoseSources, ACorTableIsReadByPhysicsAndPutOnTheHead) {
  const fs::path dir = fs::temp_directory_path() / "insitu_diagnose_sources";
  fs::remove_all(dir);
  fs::create_directories(dir);
  // Stored as glase documents it: pair (dy, dx), x-major, the error the board subtracts.
  auto reading = hw::lmc::ParseCorReading("dy-dx,x-major,--");
  ASSERT_TRUE(reading.ok()) << reading.status().ToString();
  const hw::lmc::CorFile cor =
      hw::lmc::FromCorrection(Needed, 110.0, hw::lmc::CorFormat::kJcz2, *reading);
  const std::string path = (dir / "head.cor").string();
  ASSERT_TRUE(hw::lmc::WriteCor(path, cor).ok());

  auto read = ReadCorByPhysics(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->readings[read->used], *reading) << read->summary;

  const auto t0 = std::chrono::steady_clock::now();
  auto d = RunDiagnose(path, (dir / "cor").string());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  std::printf("%s\n%.1f s for %d points\n", d->Summary().c_str(), seconds, d->n_points);
  EXPECT_EQ(d->n_points, 65 * 65);
  ASSERT_FALSE(d->cause.empty());
  EXPECT_EQ(d->cause.front(), "head_geometry");
  // The file stores whole units (110 mm / 65536 = 1.7 um): the floor of what is left.
  EXPECT_GE(1.0 - d->extended_cv_rms_mm / d->nominal_cv_rms_mm, 0.95);
  ASSERT_FALSE(d->notes.empty());
  EXPECT_NE(d->notes.front().find("dy, dx"), std::string::npos) << d->notes.front();
  EXPECT_TRUE(fs::exists(dir / "cor" / "report.json"));

  // The same table as insitu's correction CSV: the same diagnosis.
  const std::string csv = (dir / "head.csv").string();
  std::ofstream(csv) << hw::lmc::ToCorrectionCsv(cor, *reading);
  auto dc = RunDiagnose(csv, (dir / "csv").string());
  ASSERT_TRUE(dc.ok()) << dc.status().ToString();
  ASSERT_FALSE(dc->cause.empty());
  EXPECT_EQ(dc->cause.front(), "head_geometry");
  EXPECT_NEAR(dc->extended_cv_rms_mm, d->extended_cv_rms_mm, 1e-4);
}

TEST(DiagnoseSources, WhatIsNeitherIsNamed) {
  const fs::path dir = fs::temp_directory_path() / "insitu_diagnose_sources_bad";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string csv = (dir / "t.csv").string();
  std::ofstream(csv) << "a,b,c\n1,2,3\n";
  std::string source;
  auto r = LoadDiagnoseData(csv, &source);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("x_cmd_mm"), std::string::npos) << r.status().message();
  std::ofstream(dir / "t.cor") << "not a cor file";
  auto c = LoadDiagnoseData((dir / "t.cor").string(), &source);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("t.cor"), std::string::npos) << c.status().message();
}

}  // namespace
}  // namespace insitu::job
