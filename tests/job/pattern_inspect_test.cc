// `insitu pattern inspect`: a drawing's extents, areas and counts, and its preview, before any
// machine moves; through the library and through the command line.
#include "insitu/job/pattern_inspect.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace insitu::job {
namespace {

namespace fs = std::filesystem;

std::string Source(const std::string& rel) { return std::string(INSITU_SOURCE_DIR) + "/" + rel; }

// config/patterns/plate.svg: a 5 mm square with 0.5 mm rounded corners and a 1.2 mm hole.
// Its filled area is 25 - (4 - pi) 0.5^2 - pi 0.6^2 = 23.654 mm^2. The hatch measures it as
// line length x spacing: each line's ends are exact, so the error is the spacing's sampling
// of the outline's curvature, ~spacing^2 / 12 per unit of length over the 23 mm outline:
// far below 0.5 %.
TEST(PatternInspect, ExtentsAreasAndPreviewOfAnSvg) {
  PatternInspectOptions o;
  o.hatch_spacing_mm = 0.04;
  o.preview_path = (fs::temp_directory_path() / "insitu_inspect_plate.png").string();
  fs::remove(o.preview_path);
  auto in = InspectPattern(Source("config/patterns/plate.svg"), o);
  ASSERT_TRUE(in.ok()) << in.status().ToString();
  EXPECT_NEAR(in->hi.x() - in->lo.x(), 5.0, 0.005 * 5.0);
  EXPECT_NEAR(in->hi.y() - in->lo.y(), 5.0, 0.005 * 5.0);
  EXPECT_EQ(in->closed_paths, 2);
  EXPECT_EQ(in->open_paths, 0);
  const double area = 25.0 - (4.0 - M_PI) * 0.25 - M_PI * 0.36;
  EXPECT_NEAR(in->filled_area_mm2, area, 0.005 * area);
  const double perimeter = 4 * 4.0 + 2 * M_PI * 0.5 + 2 * M_PI * 0.6;
  EXPECT_NEAR(in->outline_length_mm, perimeter, 0.005 * perimeter);
  ASSERT_TRUE(fs::exists(o.preview_path));
  std::ifstream png(o.preview_path, std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
  // The scale of a mark job's placement applies: twice the size, four times the area.
  o.scale = 2.0;
  o.preview_path.clear();
  auto twice = InspectPattern(Source("config/patterns/plate.svg"), o);
  ASSERT_TRUE(twice.ok());
  EXPECT_NEAR(twice->filled_area_mm2, 4 * area, 0.005 * 4 * area);
}

// What a DXF holds and is not drawn is counted by kind and printed as a warning.
TEST(PatternInspect, SkippedEntitiesAreCountedAndPrinted) {
  PatternInspectOptions o;
  const std::string file = Source("tests/pattern/data/dxf/mesh_r12.dxf");
  auto in = InspectPattern(file, o);
  ASSERT_TRUE(in.ok()) << in.status().ToString();
  EXPECT_FALSE(in->pattern.skipped.empty());
  const std::string text = FormatInspection(file, *in);
  for (const auto& [kind, n] : in->pattern.skipped) {
    EXPECT_NE(text.find("warning: " + std::to_string(n) + " " + kind + " not drawn"),
              std::string::npos)
        << text;
  }
}

int Insitu(const std::string& args) {
  const int status = std::system((std::string(INSITU_BIN) + " " + args + " >/dev/null 2>&1").c_str());
  return WEXITSTATUS(status);
}

TEST(PatternInspect, CommandLine) {
  const fs::path out = fs::temp_directory_path() / "insitu_inspect_cli";
  fs::remove_all(out);
  EXPECT_EQ(Insitu("pattern inspect " + Source("config/patterns/ring.svg") + " --out " +
                   out.string()),
            0);
  EXPECT_TRUE(fs::exists(out / "preview.png"));
  EXPECT_EQ(Insitu("pattern inspect /nonexistent/drawing.dxf --out " + out.string()), 2);
  EXPECT_EQ(Insitu("pattern inspect " + Source("README.md") + " --out " + out.string()), 2);
  EXPECT_EQ(Insitu("pattern inspect " + Source("config/patterns/ring.svg") +
                   " --hatch-spacing -1 --out " + out.string()),
            2);
}

}  // namespace
}  // namespace insitu::job
