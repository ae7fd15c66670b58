// The inspect_grooves job on the simulated groove cell, as an operator runs it: a panel pinned by
// its tooling holes, the pocket engraved through the maskant, the grooves inspected with the
// line profiler. A panel displaced from its fixture: engraved by fixture coordinates, the
// inspection reads the displacement as the contours' offset; engraved on the scanned part, the
// offset is gone. A clamping bow shows as scale, not local error. Bad inputs fail by name,
// keeping what was measured.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "integration/job_support.h"

namespace insitu {
namespace {

namespace fs = std::filesystem;

fs::path Dir() { return fs::temp_directory_path() / "insitu_inspect_grooves_test"; }

// One rounded pocket (30 x 20 mm, 4 mm corners) and a 16 mm circle, workpiece frame (origin at
// tooling hole A, x toward hole B), as CAD writes them: a closed LWPOLYLINE with bulges and a
// CIRCLE.
std::string PocketDxf() {
  const double b = std::tan(M_PI / 8);
  const double x0 = 12, y0 = 12, x1 = 42, y1 = 32, r = 4;
  const double v[8][3] = {{x0 + r, y0, 0}, {x1 - r, y0, b}, {x1, y0 + r, 0}, {x1, y1 - r, b},
                          {x1 - r, y1, 0}, {x0 + r, y1, b}, {x0, y1 - r, 0}, {x0, y0 + r, b}};
  std::string s = "0\nSECTION\n2\nHEADER\n9\n$INSUNITS\n70\n4\n0\nENDSEC\n0\nSECTION\n2\nENTITIES\n";
  s += "0\nLWPOLYLINE\n8\nPOCKETS\n90\n8\n70\n1\n";
  char buf[96];
  for (const auto& p : v) {
    std::snprintf(buf, sizeof buf, "10\n%.4f\n20\n%.4f\n", p[0], p[1]);
    s += buf;
    if (p[2] != 0) {
      std::snprintf(buf, sizeof buf, "42\n%.12f\n", p[2]);
      s += buf;
    }
  }
  s += "0\nCIRCLE\n8\nPOCKETS\n10\n70.0\n20\n22.0\n30\n0.0\n40\n8.0\n0\nENDSEC\n0\nEOF\n";
  return s;
}

class InspectGrooves : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    testing::KeepTheWorld();
    fs::remove_all(Dir());
    fs::create_directories(Dir());
    std::ofstream(Dir() / "pockets.dxf") << PocketDxf();
    auto calibrated = testing::QuickCalibrate((Dir() / "machine.yaml").string(),
                                              (Dir() / "calibrate").string());
    ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  }

  // The shipped job on the small design, a profile every 0.5 mm.
  static Result<job::Report> Run(const std::string& name, const std::vector<std::string>& sets) {
    return testing::RunShippedJob(
        "inspect_grooves.yaml",
        testing::With({"machine.calibration=" + (Dir() / "machine.yaml").string(),
                       "design.file=" + (Dir() / "pockets.dxf").string(),
                       "inspect.profile_spacing_mm=0.5", "scan.line_spacing_mm=1.0",
                       "surface.radius_mm=1.5"},
                      sets),
        (Dir() / name).string());
  }
};

// Seed 002's metrics on the panel where the fixture holds it, against the simulator's grooves
// (tests/integration/groove_truth_test.cc measures each profile's groove against the truth):
// both contours found and matched, the grooves about 0.56 mm wide (twice the half-depth width
// of a 0.47 mm opening) and 0.3 mm deep, the contours where the design puts them. The offset's
// bound: the tooling holes measured to ~1 um (28 rim points of 25 um-spaced profiles) and each
// groove centre to ~1 um; 5 um leaves room for the gantry's 2 um repeatability.
TEST_F(InspectGrooves, AtTheFixtureTheContoursAreWhereTheDesignSays) {
  auto r = Run("nominal", {});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto& m = r->metrics;
  EXPECT_EQ(m["contours_expected"], 2.0);
  EXPECT_EQ(m["contours_matched"], 2.0);
  EXPECT_EQ(m["profiles_invalid"], 0.0);
  EXPECT_NEAR(m["groove_width_um_mean"], 560.0, 15.0);
  EXPECT_NEAR(m["groove_depth_um_mean"], 297.0, 6.0);
  EXPECT_LT(std::hypot(m["contour_offset_x_mm"], m["contour_offset_y_mm"]), 0.005);
  // 1.5 um over the contours' 15 mm half size.
  EXPECT_LT(std::abs(m["contour_scale_pct"]), 0.01);
  EXPECT_LT(m["contour_local_error_max_mm"], 0.015);
  for (const char* a : {"grooves", "contours_plot", "error_split_plot", "profile_plot", "mount"}) {
    EXPECT_TRUE(r->artifacts.count(a)) << a;
  }
}

// The panel clamped 0.3 mm right and 0.2 mm down of where the fixture's pins say. Engraved by
// fixture coordinates, the grooves sit where the pins are: on the panel, displaced by minus the
// displacement, and eq. 21's offset (design - measured) reads the displacement itself, within
// 0.01 mm (the bound; the nominal run above holds 5 um).
TEST_F(InspectGrooves, ADisplacedPanelReadsAsTheContoursOffset) {
  auto r = Run("displaced", {"world.part.position_mm=[0.3,-0.2]"});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto& m = r->metrics;
  EXPECT_EQ(m["contours_matched"], 2.0);
  EXPECT_NEAR(m["contour_offset_x_mm"], 0.3, 0.01);
  EXPECT_NEAR(m["contour_offset_y_mm"], -0.2, 0.01);
}

// The same panel engraved in situ: a scan of the part finds its tooling holes (the stripe's
// rims of each hole, ~12 chords of a line every 0.5 mm, a circle through them; the pair fitted
// to the drawing about its midpoint) and the design goes where they are: the offset is gone, to
// what the side camera can place a hole. Its rim points fall ~75 um apart along each line (rms
// 22 um each), and the reconstruction's own lateral error 50-64 mm off the field's centre adds
// its part: measured, the holes' midpoint 22 um in x and 21 um in y off, the contours' offset
// 20 um, of a 0.36 mm displacement; the bound 0.05 mm. Against fixture coordinates the offset is
// the whole displacement (the test above).
TEST_F(InspectGrooves, EngravedInSituTheOffsetIsGone) {
  auto r = Run("in_situ", {"world.part.position_mm=[0.3,-0.2]", "placement.registration=measured",
                           "scan.line_spacing_mm=0.5"});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto& m = r->metrics;
  EXPECT_EQ(m["contours_matched"], 2.0);
  std::printf("registration (%.4f, %.4f) mm for (0.3, -0.2); contour offset (%.4f, %.4f) mm\n",
              m["registration_offset_x_mm"], m["registration_offset_y_mm"],
              m["contour_offset_x_mm"], m["contour_offset_y_mm"]);
  // The registration saw the displacement...
  EXPECT_NEAR(m["registration_offset_x_mm"], 0.3, 0.05);
  EXPECT_NEAR(m["registration_offset_y_mm"], -0.2, 0.05);
  // ... and the contours sit on the design, a seventh of the displacement or less.
  EXPECT_LT(std::hypot(m["contour_offset_x_mm"], m["contour_offset_y_mm"]), 0.05);
}

// A panel bowed 0.5 mm by its clamping, engraved by fixture coordinates (its top taken as flat
// at the nominal height). The marking beam comes in slanted (x / 310 mm off the field's
// centre): meeting a top risen by dz it lands dz x slant short of where it would, toward the
// field's centre: the contours shrink. That is the scale part of the split (seed 002: the
// bending); the local error stays at the nominal run's level.
TEST_F(InspectGrooves, AClampingBowIsScaleNotLocalError) {
  auto flat = Run("flat", {});
  auto bowed = Run("bowed", {"world.part.panel_bow_mm=0.5"});
  ASSERT_TRUE(flat.ok()) << flat.status().ToString();
  ASSERT_TRUE(bowed.ok()) << bowed.status().ToString();
  auto& f = flat->metrics;
  auto& b = bowed->metrics;
  std::printf("scale: flat %.4f %%, bowed %.4f %%; local max: flat %.1f um, bowed %.1f um\n",
              f["contour_scale_pct"], b["contour_scale_pct"], 1e3 * f["contour_local_error_max_mm"],
              1e3 * b["contour_local_error_max_mm"]);
  EXPECT_LT(b["contour_scale_pct"], f["contour_scale_pct"] - 0.01);
  EXPECT_LT(b["contour_local_error_max_mm"], f["contour_local_error_max_mm"] + 0.005);
}

// Bad input fails by name, before the machine moves; a profiler that stops sending fails the job
// with the reason and keeps the profiles it sent; a panel with nothing engraved has no groove
// in any profile, and says so.
TEST_F(InspectGrooves, BadInputFailsByNameAndKeepsWhatWasMeasured) {
  std::ofstream(Dir() / "open.dxf") << "0\nSECTION\n2\nENTITIES\n0\nLINE\n8\n0\n10\n0\n20\n0\n11\n"
                                       "30\n21\n0\n0\nENDSEC\n0\nEOF\n";
  auto open = Run("open", {"design.file=" + (Dir() / "open.dxf").string()});
  ASSERT_FALSE(open.ok());
  EXPECT_NE(open.status().message().find("no closed contour"), std::string::npos)
      << open.status().message();
  EXPECT_FALSE(fs::exists(Dir() / "open" / "report.json"));  // nothing ran

  // The profiler's first 32 profiles calibrate it on the block (2 x 9) and find the tooling
  // holes (2 x 7); it stops after 28 across the grooves.
  auto stopped = Run("stopped", {"world.faults.profiler_stop_at_profile=60"});
  ASSERT_FALSE(stopped.ok());
  EXPECT_NE(stopped.status().message().find("no profile within"), std::string::npos)
      << stopped.status().message();
  std::ifstream csv(Dir() / "stopped" / "grooves.csv");
  int lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, 1 + 28);  // the header and the profiles sent

  auto blank = Run("blank", {"engrave.enabled=false"});
  ASSERT_FALSE(blank.ok());
  EXPECT_NE(blank.status().message().find("no profile holds a groove"), std::string::npos)
      << blank.status().message();
  // Every profile is in grooves.csv with its reason (the last field), none with a groove.
  std::ifstream blank_csv(Dir() / "blank" / "grooves.csv");
  int rows = 0, with_reason = 0;
  std::string l;
  std::getline(blank_csv, l);  // the header
  while (std::getline(blank_csv, l)) {
    ++rows;
    with_reason += l.back() != ',';
  }
  EXPECT_EQ(rows, 287);  // the pocket's 93.1 mm and the circle's 50.3 mm, a profile each 0.5 mm
  EXPECT_EQ(with_reason, rows);
}

}  // namespace
}  // namespace insitu

namespace insitu {
namespace {

// The profiler's mounting calibrated on the block through a GenICam 3D sensor over GigE Vision
// (the simulated profiler served on the loopback, Coord3D_C16 in 0.5 um counts): the mount the
// simulator was built with comes back (18 profiles of 3200 points, 1.5 um of speckle: the
// angles to ~1e-4 rad, the translation to a few um; the bounds 10 x those).
TEST(InspectGroovesGigE, TheMountIsCalibratedThroughAGigEVisionProfiler) {
  testing::KeepTheWorld();
  const fs::path dir = fs::temp_directory_path() / "insitu_calibrate_profiler_gige";
  fs::remove_all(dir);
  auto r = testing::RunShippedJob(
      "calibrate_profiler.yaml",
      {"machine.profiler=aravis", "machine.aravis_profiler.simulate_on=127.0.0.1",
       "output.mount_file=" + (dir / "mount.yaml").string()},
      (dir / "run").string());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const auto& truth = testing::LastSimWorld()->options().profiler.mount;
  auto& m = r->metrics;
  EXPECT_NEAR(m["mount_x_mm"], truth[0], 0.05);
  EXPECT_NEAR(m["mount_y_mm"], truth[1], 0.05);
  EXPECT_NEAR(m["mount_z_mm"], truth[2], 0.05);
  for (int k = 0; k < 3; ++k) {
    const char* name[3] = {"mount_rx_deg", "mount_ry_deg", "mount_rz_deg"};
    EXPECT_NEAR(m[name[k]], truth[3 + k], 0.06) << name[k];  // 1e-3 rad
  }
  EXPECT_LT(m["mount_fit_rms_um"], 3.0);  // the 1.5 um speckle and 0.5 um counts
  EXPECT_TRUE(fs::exists(dir / "mount.yaml"));
}

}  // namespace
}  // namespace insitu
