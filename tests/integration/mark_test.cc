// The in-situ demo end to end on the simulated cell: calibrate, scan the arc
// where it lies, put a QR code (40 um hatch), a plate (120 um hatch) and a
// dense glyph outline (path optimisation) on the measured surface, mark them,
// and let the job verify its marks. The test checks the job's own measurements
// against the bounds, then reads what the simulated laser really did:
// every crater in focus, on the part, inside the patterns' footprints, and the
// crater map reads back as the code.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "insitu/hw/machine.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/pattern/codes.h"
#include "insitu/sim/world.h"
#include "integration/job_support.h"
#include "support/zbar_qr.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

using testing::KeepTheWorld;

using insitu::testing::DecodeQr;

TEST(MarkJob, InSituDemoMarksInFocusAndVerifies) {
  KeepTheWorld();
  const fs::path dir = fs::temp_directory_path() / "insitu_mark_test";
  fs::remove_all(dir);
  const std::string cal = (dir / "machine.yaml").string();
  {
    auto calibrated = testing::QuickCalibrate(cal, (dir / "calibrate").string());
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  }
  auto report = testing::RunShippedJob("insitu_demo.yaml",
                                       {"machine.calibration=" + cal, "scan.line_spacing_mm=0.5",
                                        "surface.radius_mm=0.6", "verify.focus_points=3"},
                                       (dir / "mark").string());
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  auto& m = report->metrics;
  EXPECT_EQ(m["points_without_surface"], 0.0);
  EXPECT_TRUE(fs::exists(dir / "mark" / "galvo_list.txt"));
  EXPECT_TRUE(fs::exists(dir / "mark" / "mark.png"));

  // What the job measured of its own marks, against the bounds: spacing
  // within 2 um of 40 and of 120 um (the coaxial camera's 5 um pixels and ~0.1
  // px line centres give ~0.5 um per gap), placement within 0.1 mm (the side
  // camera's 80 um pixels over thousands of marked pixels, traced onto a
  // surface known to ~0.03 mm), and the focus error under a quarter of the
  // marking beam's depth of focus (+-z_R = +-0.91 mm for a 40 um waist, M^2
  // 1.3, 1064 nm: 1.82 / 4 = 0.45 mm).
  ASSERT_TRUE(m.count("line_spacing_40_um") && m.count("line_spacing_120_um"));
  EXPECT_NEAR(m["line_spacing_40_um"], 40.0, 2.0);
  EXPECT_NEAR(m["line_spacing_120_um"], 120.0, 2.0);
  ASSERT_TRUE(m.count("placement_error_mm"));
  EXPECT_LE(m["placement_error_mm"], 0.1);
  // Seed 004 on the glyph's dense outline: far fewer points, within the 2 um
  // asked for.
  EXPECT_LT(m["path_points_out"], 0.25 * m["path_points_in"]);
  EXPECT_LE(m["path_max_error_um"], 2.0);
  ASSERT_TRUE(m.count("focus_error_max_mm"));
  EXPECT_LT(m["focus_error_max_mm"], 0.45);
  std::printf("spacing %.2f / %.2f um, placement %.3f mm, focus %.3f mm\n", m["line_spacing_40_um"],
              m["line_spacing_120_um"], m["placement_error_mm"], m["focus_error_max_mm"]);

  // What the simulated laser really did (truth the job never sees).
  ASSERT_NE(testing::LastSimWorld(), nullptr);
  const auto& pulses = testing::LastSimWorld()->mark_pulses();
  ASSERT_GT(pulses.size(), 10000u);
  auto code = pattern::QrCodeMask("insitu demo 0001", 'M');
  ASSERT_TRUE(code.ok());
  // Items as placed in the demo: centre, half size, rotation (3 deg, square to
  // the part).
  struct Item {
    Eigen::Vector2d centre;
    double half;
  };
  // The glyph (4.2 x 6.2 mm) is bounded by its larger half size.
  const Item items[3] = {
      {{1.0, -8.0}, 0.5 * code->width * 0.3}, {{1.5, 4.0}, 2.5}, {{1.5, 12.0}, 3.1}};
  const double rot = 3.0 * M_PI / 180.0;
  const auto local = [&](const Eigen::Vector3d& p, const Item& it) {
    const Eigen::Vector2d d = p.head<2>() - it.centre;
    return Eigen::Vector2d(std::cos(rot) * d.x() + std::sin(rot) * d.y(),
                           -std::sin(rot) * d.x() + std::cos(rot) * d.y());
  };
  double worst_defocus = 0.0;
  int off_part = 0, outside = 0;
  for (const sim::MarkPulse& p : pulses) {
    worst_defocus = std::max(worst_defocus, std::abs(p.defocus_mm));
    off_part += !p.on_part;
    // Crater radius + the placement bound above (0.1 mm): a pattern's corner far from its
    // centre moves by the placement and the draping over the measured surface together, and
    // a stray pulse (the laser on during a jump, a pattern in the wrong place) lies mm away.
    const double r = 0.5 * p.diameter_mm + 0.1;
    bool inside = false;
    for (const Item& it : items) {
      const Eigen::Vector2d q = local(p.point_in_world, it);
      inside |= std::abs(q.x()) <= it.half + r && std::abs(q.y()) <= it.half + r;
    }
    outside += !inside;
  }
  // The surface is measured to ~0.03 mm, so the real focus error stays near
  // that, far under the quarter depth of focus.
  EXPECT_LT(worst_defocus, 0.1);
  EXPECT_EQ(off_part, 0);
  EXPECT_EQ(outside, 0);
  std::printf("%zu pulses, worst defocus %.3f mm\n", pulses.size(), worst_defocus);

  // The QR code's crater map, seen from above at 20 um per pixel in the code's
  // own frame, reads back as the code: placed, oriented and marked right end to
  // end.
  const double px = 0.02, margin = 4 * 0.3, half = items[0].half;
  const int n = static_cast<int>(std::ceil(2 * (half + margin) / px));
  cv::Mat map(n, n, CV_8UC1, cv::Scalar(255));
  for (const sim::MarkPulse& p : pulses) {
    const Eigen::Vector2d q = local(p.point_in_world, items[0]);
    if (std::abs(q.x()) > half + margin || std::abs(q.y()) > half + margin) continue;
    const double u = (q.x() + half + margin) / px;
    const double v = (half + margin - q.y()) / px;  // +y up
    cv::circle(map, cv::Point(static_cast<int>(u), static_cast<int>(v)),
               std::max(1, static_cast<int>(std::lround(0.5 * p.diameter_mm / px))), cv::Scalar(0),
               cv::FILLED);
  }
  // As an imager would: blurred over ~2 pixels (40 um), so the pulse texture
  // inside a module does not read as structure.
  cv::GaussianBlur(map, map, cv::Size(0, 0), 2.0);
  cv::threshold(map, map, 128, 255, cv::THRESH_BINARY);
  cv::imwrite((dir / "crater_map.png").string(), map);
  EXPECT_EQ(DecodeQr(map), "insitu demo 0001");
}

}  // namespace
}  // namespace insitu
