// The mark job end to end on the simulated cell: calibrate, scan the arc where it lies, put a
// QR code on the measured surface, mark it. The test (not the product) then reads what the
// simulated laser did: every crater in focus, on the part, inside the code's footprint, and
// the crater map reads back as the code.
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "insitu/hw/machine.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/pattern/codes.h"
#include "insitu/sim/world.h"
#include "integration/job_support.h"
#include "support/zbar_qr.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

std::shared_ptr<sim::SimWorld> g_world;  // the last world the "sim" backend brought up

void KeepTheWorld() {
  hw::RegisterBackend("sim", [](const hw::MachineConfig& config) -> Result<hw::Machine> {
    INSITU_RETURN_IF_ERROR(config.world.Validate());
    g_world = std::make_shared<sim::SimWorld>(config.world);
    return hw::MakeSimMachine(g_world);
  });
}

using insitu::testing::DecodeQr;

TEST(MarkJob, QrCodeOnTheArcInFocus) {
  KeepTheWorld();
  const fs::path dir = fs::temp_directory_path() / "insitu_mark_test";
  fs::remove_all(dir);
  const std::string cal = (dir / "machine.yaml").string();
  {
    auto calibrated = testing::QuickCalibrate(cal, (dir / "calibrate").string());
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  }
  auto report = testing::RunShippedJob(
      "mark_qr_arc.yaml",
      {"machine.calibration=" + cal, "scan.line_spacing_mm=0.5", "surface.radius_mm=0.6"},
      (dir / "mark").string());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->metrics["points_without_surface"], 0.0);
  EXPECT_TRUE(fs::exists(dir / "mark" / "galvo_list.txt"));
  ASSERT_NE(g_world, nullptr);
  const auto& pulses = g_world->mark_pulses();
  ASSERT_GT(pulses.size(), 10000u);

  // The code: 0.3 mm modules centred at (1, -2).
  auto code = pattern::QrCodeMask("insitu arc 0001", 'M');
  ASSERT_TRUE(code.ok());
  const double half = 0.5 * code->width * 0.3;
  // Depth of focus of the marking beam: +-z_R = +-0.91 mm (40 um waist, M^2 1.3, 1064 nm);
  // the issue asks for focus errors under a quarter of it (0.45 mm). The surface is measured
  // to ~0.03 mm, so in practice the focus error stays near that.
  double worst_defocus = 0.0;
  int off_part = 0, outside = 0;
  for (const sim::MarkPulse& p : pulses) {
    worst_defocus = std::max(worst_defocus, std::abs(p.defocus_mm));
    off_part += !p.on_part;
    const double r = 0.5 * p.diameter_mm + 0.05;  // crater radius + placement tolerance
    outside += std::abs(p.point_in_world.x() - 1.0) > half + r ||
               std::abs(p.point_in_world.y() + 2.0) > half + r;
  }
  EXPECT_LT(worst_defocus, 0.1);
  EXPECT_EQ(off_part, 0);
  EXPECT_EQ(outside, 0);
  std::printf("%zu pulses, worst defocus %.3f mm\n", pulses.size(), worst_defocus);

  // The crater map, seen from above at 20 um per pixel, reads back as the code: the pattern
  // is placed, oriented and marked right end to end.
  const double px = 0.02, margin = 4 * 0.3;
  const int n = static_cast<int>(std::ceil(2 * (half + margin) / px));
  cv::Mat map(n, n, CV_8UC1, cv::Scalar(255));
  for (const sim::MarkPulse& p : pulses) {
    const double u = (p.point_in_world.x() - 1.0 + half + margin) / px;
    const double v = (half + margin - (p.point_in_world.y() + 2.0)) / px;  // +y up
    cv::circle(map, cv::Point(static_cast<int>(u), static_cast<int>(v)),
               std::max(1, static_cast<int>(std::lround(0.5 * p.diameter_mm / px))), cv::Scalar(0),
               cv::FILLED);
  }
  // As an imager would: blurred over ~2 pixels (40 um), so the pulse texture inside a module
  // does not read as structure.
  cv::GaussianBlur(map, map, cv::Size(0, 0), 2.0);
  cv::threshold(map, map, 128, 255, cv::THRESH_BINARY);
  cv::imwrite((dir / "crater_map.png").string(), map);
  EXPECT_EQ(DecodeQr(map), "insitu arc 0001");
}

}  // namespace
}  // namespace insitu
