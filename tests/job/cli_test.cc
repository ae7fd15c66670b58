// The operator's command line: bad input gets one clear line naming the file, key or line and
// a non-zero exit; nothing is written for a job that never started.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;

struct CliRun {
  int exit_code;
  std::string err;
};

CliRun Insitu(const std::string& args) {
  const std::string err_file = (fs::temp_directory_path() / "insitu_cli_err.txt").string();
  const std::string cmd = std::string(INSITU_BIN) + " " + args + " 2>" + err_file + " >/dev/null";
  const int status = std::system(cmd.c_str());
  std::ifstream f(err_file);
  std::string err((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  return {WEXITSTATUS(status), err};
}

std::string Job() { return std::string(INSITU_SOURCE_DIR) + "/config/jobs/scan_step_gauge.yaml"; }

std::string WriteJob(const std::string& name, const std::string& text) {
  const fs::path p = fs::temp_directory_path() / name;
  std::ofstream(p) << text;
  return p.string();
}

int Lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

TEST(Cli, VersionAndHelp) {
  EXPECT_EQ(Insitu("--version").exit_code, 0);
  EXPECT_EQ(Insitu("--help").exit_code, 0);
  EXPECT_EQ(Insitu("run --help").exit_code, 0);
}

TEST(Cli, MissingJobFileNamesIt) {
  const CliRun r = Insitu("run /nonexistent/job.yaml");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("/nonexistent/job.yaml"), std::string::npos) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
}

TEST(Cli, MalformedYamlNamesTheLine) {
  const std::string job = WriteJob("bad_yaml.yaml", "job: scan\nscan:\n  x_start_mm: [1, 2\n");
  const CliRun r = Insitu("run " + job);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("bad_yaml.yaml:"), std::string::npos) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
}

TEST(Cli, UnknownKeyIsNamed) {
  const CliRun r = Insitu("run " + Job() + " --set scan.line_spacng_mm=0.5 --out /tmp/insitu_cli");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("scan.line_spacng_mm"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("unknown"), std::string::npos) << r.err;
}

TEST(Cli, OutOfRangeValuesAreNamed) {
  const CliRun exposure = Insitu("run " + Job() + " --set camera.exposure_ms=-5 --out /tmp/insitu_cli");
  EXPECT_EQ(exposure.exit_code, 2);
  EXPECT_NE(exposure.err.find("exposure_ms"), std::string::npos) << exposure.err;
  EXPECT_EQ(Lines(exposure.err), 1) << exposure.err;
  const CliRun spacing = Insitu("run " + Job() + " --set scan.line_spacing_mm=0 --out /tmp/insitu_cli");
  EXPECT_EQ(spacing.exit_code, 2);
  EXPECT_NE(spacing.err.find("line_spacing_mm"), std::string::npos) << spacing.err;
  const CliRun world = Insitu("run " + Job() + " --set world.camera.f_number=0 --out /tmp/insitu_cli");
  EXPECT_EQ(world.exit_code, 2);
  EXPECT_NE(world.err.find("f_number"), std::string::npos) << world.err;
  const CliRun type = Insitu("run " + Job() + " --set scan.speed_mm_per_s=fast --out /tmp/insitu_cli");
  EXPECT_EQ(type.exit_code, 2);
  EXPECT_NE(type.err.find("scan.speed_mm_per_s"), std::string::npos) << type.err;
}

// An LMC board's settings: a source it does not have, a setting its source has no use for,
// and a capture that is not one, each named.
TEST(Cli, LmcSettingsAndCapturesAreChecked) {
  const std::string job = std::string(INSITU_SOURCE_DIR) + "/config/jobs/mark_plate_lmc.yaml";
  const CliRun source =
      Insitu("run " + job + " --set machine.lmc.source=diode --out /tmp/insitu_cli");
  EXPECT_EQ(source.exit_code, 2);
  EXPECT_NE(source.err.find("source"), std::string::npos) << source.err;
  const CliRun width =
      Insitu("run " + job + " --set machine.lmc.pulse_width_ns=100 --out /tmp/insitu_cli");
  EXPECT_EQ(width.exit_code, 2);
  EXPECT_NE(width.err.find("pulse_width_ns"), std::string::npos) << width.err;
  const CliRun missing = Insitu("lmc decode /nonexistent/traffic.pcapng");
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.err.find("/nonexistent/traffic.pcapng"), std::string::npos) << missing.err;
  const CliRun junk = Insitu("lmc decode " + Job());  // a YAML job, not a capture
  EXPECT_EQ(junk.exit_code, 2);
  EXPECT_NE(junk.err.find("usbmon"), std::string::npos) << junk.err;
}

TEST(Cli, BadSetSyntaxAndUnknownJobKind) {
  EXPECT_EQ(Insitu("run " + Job() + " --set nonsense").exit_code, 2);
  const std::string job = WriteJob("kind.yaml", "job: teleport\n");
  const CliRun r = Insitu("run " + job);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("teleport"), std::string::npos) << r.err;
}

TEST(Cli, CalibrationForAnotherCameraIsRefused) {
  const CliRun r = Insitu("run " + Job() + " --set world.camera.width_px=2592 " +
                       "--set world.camera.height_px=1944 --out /tmp/insitu_cli");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("2592"), std::string::npos) << r.err;
}

}  // namespace

namespace {

// A mark job around a pattern section (YAML, indented two spaces under `pattern:`).
std::string MarkJobWith(const std::string& name, const std::string& pattern,
                        const std::string& extra = "") {
  return WriteJob(name, "job: mark\nmachine: {backend: sim, calibration: " + std::string(INSITU_SOURCE_DIR) +
                            "/calib/as_designed.yaml}\nworld: " +
                            std::string(INSITU_SOURCE_DIR) + "/config/worlds/default.yaml\n" +
                            "pattern:\n" + pattern + extra);
}

// A bad pattern fails before the machine moves: one line naming the job, the pattern and the
// problem, exit 2, nothing scanned.
TEST(Cli, MarkJobRefusesBadPatterns) {
  const std::string png = WriteJob("corrupt.png", "this is not an image");
  const CliRun corrupt = Insitu(
      "run " + MarkJobWith("m1.yaml", "  kind: raster\n  file: " + png + "\n") + " --out /tmp/insitu_cli");
  EXPECT_EQ(corrupt.exit_code, 2);
  EXPECT_NE(corrupt.err.find("corrupt.png"), std::string::npos) << corrupt.err;
  EXPECT_NE(corrupt.err.find("pattern"), std::string::npos) << corrupt.err;
  EXPECT_EQ(Lines(corrupt.err), 1) << corrupt.err;

  const std::string svg = WriteJob("empty.svg", "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>");
  const CliRun empty = Insitu(
      "run " + MarkJobWith("m2.yaml", "  kind: svg\n  file: " + svg + "\n") + " --out /tmp/insitu_cli");
  EXPECT_EQ(empty.exit_code, 2);
  EXPECT_NE(empty.err.find("empty.svg"), std::string::npos) << empty.err;

  const CliRun mapping = Insitu("run " + MarkJobWith("m3.yaml", "  kind: qr\n  data: x\n",
                                                     "placement: {mapping: bend}\n") +
                                " --out /tmp/insitu_cli");
  EXPECT_EQ(mapping.exit_code, 2);
  EXPECT_NE(mapping.err.find("mapping"), std::string::npos) << mapping.err;

  const std::string items =
      WriteJob("items.yaml",
               "job: mark\nmachine: {backend: sim, calibration: " + std::string(INSITU_SOURCE_DIR) +
                   "/calib/as_designed.yaml}\nworld: " + std::string(INSITU_SOURCE_DIR) +
                   "/config/worlds/default.yaml\nitems: [{pattern: {kind: qr, data: x}, hatch: "
                   "{spacing_mm: -1}}]\n");
  const CliRun item = Insitu("run " + items + " --out /tmp/insitu_cli");
  EXPECT_EQ(item.exit_code, 2);
  EXPECT_NE(item.err.find("spacing_mm"), std::string::npos) << item.err;
}

}  // namespace

namespace {

// insitu diagnose on the shipped measured data (a table of moves: 14 measured from the 15th, its
// reference) writes the contract's report and the plot; bad data is one clear line naming the
// file, the line and the column.
TEST(Cli, DiagnoseTheMeasuredFieldAndRefuseBadData) {
  const fs::path out = fs::temp_directory_path() / "insitu_cli_diagnose";
  fs::remove_all(out);
  const CliRun ok = Insitu("diagnose " + std::string(INSITU_SOURCE_DIR) +
                           "/data/measured/galvo_field_hao2009.csv --out " + out.string());
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  std::ifstream f(out / "report.json");
  const std::string report((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  for (const char* key : {"\"n_points\": 14", "\"nominal\"", "\"effects\"", "\"cause\"",
                          "\"extended\"", "\"gain\"", "\"noise_mm\"", "\"unexplained\""}) {
    EXPECT_NE(report.find(key), std::string::npos) << key;
  }
  EXPECT_TRUE(fs::exists(out / "residuals.png"));

  const std::string bad = WriteJob("bad_field.csv", "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm\n0,0,0,0\n1,0,one,0\n");
  const CliRun r = Insitu("diagnose " + bad + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("bad_field.csv:3"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("x_meas_mm"), std::string::npos) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
}

}  // namespace

namespace {

// An LMC board's correction in and out: insitu's table exported as a .cor file (in the
// documented convention) reads back as the same field (to the JCZ format's whole units, 1.7 um
// on a 110 mm lens) when the reading is named (four arbitrary nodes: not a head's table, whose
// reading the physics could show); a table of noise is not read by guess: the import refuses
// and names --reading. A file that is not a .cor is named.
TEST(Cli, CorFilesExportAndImport) {
  const fs::path dir = fs::temp_directory_path() / "insitu_cli_cor";
  fs::create_directories(dir);
  const std::string table =
      WriteJob("insitu_cli_cor_table.csv",
               "x_mm,y_mm,dx_mm,dy_mm\n-50,-50,0.01,-0.02\n50,-50,0.03,0.0\n-50,50,0,0\n"
               "50,50,-0.01,0.02\n");
  const std::string cor = (dir / "field.cor").string();
  const std::string back = (dir / "field.csv").string();
  ASSERT_EQ(Insitu("cor export " + table + " --lens 110 --out " + cor).exit_code, 0);
  EXPECT_EQ(fs::file_size(cor), 33840u);
  {
    // Noise of 20 um on a 5 x 5 grid: no head in it.
    std::string noise = "x_mm,y_mm,dx_mm,dy_mm\n";
    unsigned state = 7;
    const auto next = [&] {
      return static_cast<int>(((state = state * 1103515245u + 12345u) >> 8) % 41) - 20;
    };
    for (int j = 0; j < 5; ++j) {
      for (int i = 0; i < 5; ++i) {
        noise += std::to_string(-50 + 25 * i) + "," + std::to_string(-50 + 25 * j) + "," +
                 std::to_string(next() * 1e-3) + "," + std::to_string(next() * 1e-3) + "\n";
      }
    }
    const std::string noise_csv = WriteJob("insitu_cli_cor_noise.csv", noise);
    const std::string noise_cor = (dir / "noise.cor").string();
    const std::string noise_back = (dir / "noise_back.csv").string();
    ASSERT_EQ(Insitu("cor export " + noise_csv + " --lens 110 --out " + noise_cor).exit_code, 0);
    const CliRun guess = Insitu("cor import " + noise_cor + " --out " + noise_back);
    EXPECT_EQ(guess.exit_code, 2);
    EXPECT_NE(guess.err.find("cannot be decided"), std::string::npos) << guess.err;
    EXPECT_NE(guess.err.find("--reading"), std::string::npos) << guess.err;
    EXPECT_FALSE(fs::exists(noise_back));
  }
  ASSERT_EQ(Insitu("cor import " + cor + " --reading dx-dy,y-major,-- --out " + back).exit_code, 0);
  std::ifstream f(back);
  std::string line;
  int nodes = 0;
  double worst = 0.0;
  while (std::getline(f, line)) {
    double x, y, dx, dy;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf", &x, &y, &dx, &dy) != 4) continue;
    ++nodes;
    if (x < -50 || x > 50 || y < -50 || y > 50) continue;  // beyond the table: its edge
    // The table's own bilinear offset at the node.
    const double u = (x + 50) / 100, v = (y + 50) / 100;
    const double ex = (1 - u) * (1 - v) * 0.01 + u * (1 - v) * 0.03 + u * v * -0.01;
    const double ey = (1 - u) * (1 - v) * -0.02 + u * v * 0.02;
    worst = std::max({worst, std::abs(dx - ex), std::abs(dy - ey)});
  }
  EXPECT_EQ(nodes, 65 * 65);
  EXPECT_LT(worst, 0.5 * 110.0 / 65536 + 1e-9);
  const CliRun bad = Insitu("cor import " + table + " --out " + back);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("not a .cor file"), std::string::npos) << bad.err;
}

}  // namespace
