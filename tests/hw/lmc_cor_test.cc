// .cor files and their readings (hw/lmc_cor.h): the correction of a simulated LMC head
// stored in a known convention is read back in that convention by the two-mirror head model
// (fit/cor_physics.h), as `insitu cor import` does; files are written back byte for byte;
// export, import and export again give the same file; malformed files are named with what is
// wrong. (tests/hw/lmc_test.cc covers the formats' round trip of values, a short file and the
// upload's words.)
#include "insitu/hw/lmc_cor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

#include "hw/lmc/sim_board.h"
#include "insitu/fit/cor_physics.h"
#include "insitu/hw/cell.h"
#include "insitu/optics/scan_head.h"
#include "insitu/pattern/correction_table.h"
#include "insitu/sim/world.h"

namespace insitu::hw::lmc {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector2d;

std::string Temp(const std::string& name) { return (fs::temp_directory_path() / name).string(); }

std::string Bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

void Put(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// The simulated head as an LMC board without a table drives it: the simulator's optics
// (sim::WorldOptions, f = 255 mm) as built with lens distortion, both mirror axes tilted and
// zero offsets, and the board's linear map from units to optical angles, a = x / f + a0.
// The head's correction is computed here from the same optics: the command whose spot lands on
// the node, minus the node.
struct SimLmcHead {
  optics::HeadGeometry built;
  double x0_mrad = 0.4, y0_mrad = -0.3;

  SimLmcHead() {
    sim::WorldOptions w;
    built = w.scan_head.optics;
    built.ftheta_c3 = 0.03;
    built.ftheta_c5 = -0.05;
    built.x_axis_tilt_mrad = 1.0;
    built.y_axis_tilt_mrad = -0.5;
  }

  Vector2d Correction(double x, double y) const {
    optics::MirrorAngles a;
    EXPECT_TRUE(optics::ScanOptics(built).Solve(x, y, 0.0, &a)) << x << ", " << y;
    const double f = built.focal_length_mm;
    return Vector2d((a.x_rad - x0_mrad * 1e-3) * f, (a.y_rad - y0_mrad * 1e-3) * f) -
           Vector2d(x, y);
  }
};

// The 16 readings of a file, as `insitu cor import` fits them (apps/insitu/main.cc).
std::vector<fit::CorReadingCandidate> Candidates(const CorFile& cor) {
  std::vector<fit::CorReadingCandidate> out;
  for (const CorReading& r : AllCorReadings()) {
    fit::CorReadingCandidate c;
    c.name = r.Code();
    c.documented = IsDocumentedReading(r);
    for (int i = 0; i < 65; ++i) {
      for (int j = 0; j < 65; ++j) {
        c.node_mm.push_back(cor.NodeMm(i, j));
        c.offset_mm.push_back(cor.OffsetMm(i, j, r));
      }
    }
    out.push_back(std::move(c));
  }
  return out;
}

// The board's lens (163 mm: 2.5 um units) over the simulated head's +-70 mm field with a
// margin, as tests/hw/lmc_test.cc's SimHeadBoard. Corner corrections reach ~4 mm (two-mirror
// distortion at 0.32 rad), ~1600 units: well inside the board's +-32767.
constexpr double kLens = 163.0;

TEST(LmcCor, TheHeadModelReadsASimulatedHeadsTableInItsConvention) {
  const SimLmcHead head;
  const auto correction = [&](double x, double y) { return head.Correction(x, y); };
  // The documented convention (both transpositions); meerk40t's; and one no source names.
  for (const char* code :
       {"dy-dx,x-major,--", "dx-dy,y-major,--", "dx-dy,x-major,++", "dx-dy,y-major,-+"}) {
    for (const CorFormat format : {CorFormat::kJcz2, CorFormat::kLmc1}) {
      SCOPED_TRACE(std::string(code) + (format == CorFormat::kJcz2 ? " jcz" : " lmc1"));
      const auto known = ParseCorReading(code);
      ASSERT_TRUE(known.ok());
      const std::string path = Temp("insitu_sim_head.cor");
      ASSERT_TRUE(WriteCor(path, FromCorrection(correction, kLens, format, *known)).ok());
      const auto cor = ReadCor(path);
      ASSERT_TRUE(cor.ok()) << cor.status().ToString();
      const std::vector<fit::CorReadingCandidate> candidates = Candidates(*cor);
      fit::CorPhysicsOptions options;
      options.lens_mm = cor->lens_mm();
      const auto choice = fit::ChooseCorReading(candidates, options);
      ASSERT_TRUE(choice.ok()) << choice.status().ToString();
      for (size_t k = 0; k < candidates.size(); ++k) {
        std::printf("  %-18s %6.2f %%\n", candidates[k].name.c_str(),
                    100 * choice->fits[k].explained);
      }
      ASSERT_TRUE(choice->decided_by_physics) << choice->warning;
      const CorReading chosen = AllCorReadings()[choice->chosen];
      EXPECT_EQ(chosen.Code(), known->Code());
      // The table is the head's own correction to whole units (2.5 um: rms 0.7 um per
      // component, 1 um as a vector, of a table of ~1.5 mm rms): the head explains >= 99 %,
      // and no other reading comes within 15 points (measured: the next best 71.8 %).
      EXPECT_GE(choice->fits[choice->chosen].explained, 0.99);
      EXPECT_LT(choice->fits[choice->runner_up].explained,
                choice->fits[choice->chosen].explained - 0.15);
      // Read that way, the table is the head's correction in the galvo frame, to half a unit.
      const double unit_mm = kLens / 65536;
      double worst = 0;
      for (int i = 0; i < 65; i += 8) {
        for (int j = 0; j < 65; j += 8) {
          const Vector2d p = cor->NodeMm(i, j);
          worst = std::max(
              worst,
              (cor->OffsetMm(i, j, chosen) - correction(p.x(), p.y())).cwiseAbs().maxCoeff());
        }
      }
      EXPECT_LE(worst, 0.5 * unit_mm + 1e-9);
    }
  }
}

// A generated head's table round-trips through export, import and the emulated board to the
// same marks. The head is driven linearly (an analogue head behind an LMC board: the world's
// own_correction off), so the board's uploaded table is all the correction there is; the
// board applies it as the documented convention says, which is also how insitu exports it for
// the board's wiring (swap_xy). The file is uploaded as stored. For both wirings: the physics
// reads the file back in the reading it was written in, the CSV exports to the same bytes, and
// the marks land where asked; the table of the other wiring (the transposed reading) misses
// by the two-mirror distortion's asymmetry.
TEST(LmcCor, AHeadsTableRoundTripsThroughTheBoardToTheSameMarks) {
  const SimLmcHead head;
  const auto correction = [&](double x, double y) { return head.Correction(x, y); };
  for (const bool swap : {false, true}) {
    SCOPED_TRACE(swap ? "swap_xy" : "no swap");
    const CorReading reading = DocumentedReading(swap);
    const std::string path = Temp("insitu_round_trip.cor"), again = Temp("insitu_round_trip2.cor");
    ASSERT_TRUE(WriteCor(path, FromCorrection(correction, kLens, CorFormat::kJcz2, reading)).ok());
    const auto cor = ReadCor(path);
    ASSERT_TRUE(cor.ok());
    fit::CorPhysicsOptions options;
    options.lens_mm = cor->lens_mm();
    const auto choice = fit::ChooseCorReading(Candidates(*cor), options);
    ASSERT_TRUE(choice.ok()) << choice.status().ToString();
    ASSERT_GE(choice->chosen, 0) << choice->warning;
    EXPECT_EQ(AllCorReadings()[choice->chosen], reading);
    EXPECT_GE(choice->fits[choice->chosen].explained, 0.99);
    const std::string csv = ToCorrectionCsv(*cor, reading);
    const auto table = pattern::CorrectionTable::Parse(csv, "imported.csv");
    ASSERT_TRUE(table.ok());
    ASSERT_TRUE(
        WriteCor(again, FromCorrection([&](double x, double y) { return table->OffsetAt(x, y); },
                                       kLens, CorFormat::kJcz2, reading))
            .ok());
    ASSERT_TRUE(Bytes(path) == Bytes(again)) << "the second export differs";

    // The head behind the board.
    sim::WorldOptions w;
    w.part.kind = "none";
    w.scan_head.optics = head.built;
    w.scan_head.design.focal_length_mm = head.built.focal_length_mm;
    w.scan_head.x_zero_offset_mrad = head.x0_mrad;
    w.scan_head.y_zero_offset_mrad = head.y0_mrad;
    w.scan_head.own_correction = false;
    // Where the head puts the beam for command p (galvo frame, mm), through a board set up as
    // `o` that was given `file`.
    const auto landed = [&](const BoardOptions& o, const CorFile& file,
                            std::vector<Vector2d>* asked) {
      auto world = std::make_shared<sim::SimWorld>(w);
      SimBoard board(world, o);
      EXPECT_TRUE(UploadCorrection(board, ToBoard(file)).ok());
      const optics::ScanOptics built(head.built);
      std::vector<Vector2d> out;
      asked->clear();
      for (int i = -3; i <= 3; ++i) {
        for (int j = -3; j <= 3; ++j) {
          const Eigen::Vector3d p(20.0 * i, 20.0 * j, 0.0);
          optics::MirrorAngles a;
          EXPECT_TRUE(world->CommandToAngles(p, &a));
          asked->push_back(p.head<2>());
          out.push_back(built.Trace(a).focal_point_in_world.head<2>());
        }
      }
      return out;
    };
    BoardOptions o;
    o.lens_mm = kLens;
    o.swap_xy = swap;
    std::vector<Vector2d> asked;
    const std::vector<Vector2d> spots = landed(o, *ReadCor(again), &asked);
    double worst = 0;
    for (size_t k = 0; k < spots.size(); ++k) worst = std::max(worst, (spots[k] - asked[k]).norm());
    // Whole units (2.5 um: <= 1.8 um as a vector) and the bilinear steps of 2.5 mm over a
    // correction whose curvature reaches ~4e-3 /mm at +-60 mm (h^2 / 8 * 4e-3 ~ 3 um).
    std::printf("  the head's table through the board: worst %.2f um from where asked\n",
                worst * 1e3);
    EXPECT_LE(worst, 0.005);
    // The same numbers on a board of the other wiring: the table is read transposed.
    BoardOptions other = o;
    other.swap_xy = !swap;
    const std::vector<Vector2d> wrong = landed(other, *ReadCor(again), &asked);
    double wrong_worst = 0;
    for (size_t k = 0; k < wrong.size(); ++k) {
      wrong_worst = std::max(wrong_worst, (wrong[k] - asked[k]).norm());
    }
    std::printf("  on a board of the other wiring: worst %.0f um\n", wrong_worst * 1e3);
    EXPECT_GT(wrong_worst, 0.1);
    // The board-word writer gives the same file where the board has no flips.
    const auto drive = [&](const Vector2d& p) { return Vector2d(p + correction(p.x(), p.y())); };
    ASSERT_TRUE(WriteCor(again, BoardTableFromDrive(drive, o, CorFormat::kJcz2)).ok());
    EXPECT_TRUE(Bytes(path) == Bytes(again)) << "BoardTableFromDrive differs from FromCorrection";
    // A board with flipped axes: the table is in its words, node by node, and lands as well.
    for (const auto& [fx, fy] : {std::pair{true, false}, {false, true}, {true, true}}) {
      BoardOptions flipped = o;
      flipped.flip_x = fx;
      flipped.flip_y = fy;
      const std::vector<Vector2d> through =
          landed(flipped, BoardTableFromDrive(drive, flipped, CorFormat::kJcz2), &asked);
      double flipped_worst = 0;
      for (size_t k = 0; k < through.size(); ++k) {
        flipped_worst = std::max(flipped_worst, (through[k] - asked[k]).norm());
      }
      EXPECT_LE(flipped_worst, 0.005) << "flip_x " << fx << ", flip_y " << fy;
    }
  }
  // And a machine whose board gets a file comes up, the file uploaded as stored.
  const std::string path = Temp("insitu_sim_head_upload.cor");
  ASSERT_TRUE(
      WriteCor(path, FromCorrection(correction, kLens, CorFormat::kJcz2, DocumentedReading(false)))
          .ok());
  auto world = std::make_shared<sim::SimWorld>(sim::WorldOptions{});
  BoardOptions board_options;
  board_options.lens_mm = kLens;
  SimBoard board(world, board_options);
  ASSERT_TRUE(UploadCorrection(board, ToBoard(*ReadCor(path))).ok());
  ASSERT_EQ(board.log().correction, ToBoard(*ReadCor(path)).offsets);
  MachineConfig config;
  config.scanner = "lmc";
  config.lmc.transport = "sim_board";
  config.lmc.board = board_options;
  config.lmc.correction_file = path;
  const auto machine = CreateMachine(config);
  EXPECT_TRUE(machine.ok()) << machine.status().ToString();
}

// Files from other writers: header fields insitu does not use, trailing bytes, 8-bit labels,
// fractional and negative-zero doubles: read and written again, the same bytes.
TEST(LmcCor, ReadThenWriteIsTheSameFile) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> byte(0, 255), offset(-20000, 20000);
  const auto append = [](std::string* b, auto v) {
    b->append(reinterpret_cast<const char*>(&v), sizeof v);
  };
  const double scale = 65536.0 / 110.0;
  // JCZ_COR_2_1, UTF-16 label, noise in the 6 padding bytes and the 4 trailing ones.
  std::string jcz;
  for (char c : std::string("JCZ_COR_2_1")) {
    jcz.push_back(c);
    jcz.push_back('\0');
  }
  for (int k = 0; k < 6; ++k) jcz.push_back(static_cast<char>(byte(rng)));
  append(&jcz, scale);
  for (int n = 0; n < 2 * 4225; ++n) append(&jcz, static_cast<int32_t>(offset(rng)));
  for (int k = 0; k < 4; ++k) jcz.push_back(static_cast<char>(byte(rng)));
  ASSERT_EQ(jcz.size(), 33840u);
  // LMC1COR_1.0, 8-bit label, other header doubles set, fractional offsets, -0.0, a tail.
  std::string lmc = "LMC1COR_1.0";
  lmc.resize(24, '\0');
  for (int k = 0; k < 63; ++k) append(&lmc, k == 43 ? scale : 0.25 * k);
  for (int n = 0; n < 2 * 4225; ++n) append(&lmc, n == 7 ? -0.0 : offset(rng) / 7.0);
  lmc += "tail";
  for (const std::string& bytes : {jcz, lmc}) {
    const std::string in = Temp("insitu_foreign.cor"), out = Temp("insitu_foreign_again.cor");
    Put(in, bytes);
    const auto cor = ReadCor(in);
    ASSERT_TRUE(cor.ok()) << cor.status().ToString();
    EXPECT_DOUBLE_EQ(cor->lens_mm(), 110.0);
    ASSERT_TRUE(WriteCor(out, *cor).ok());
    EXPECT_TRUE(Bytes(out) == bytes) << "not the same bytes";
  }
}

// insitu's table exported in a reading, imported (the CSV names the reading) and exported
// again: the same file, in both formats and whatever the reading.
TEST(LmcCor, ExportImportExportIsTheSameFile) {
  const SimLmcHead head;
  const auto correction = [&](double x, double y) { return head.Correction(x, y); };
  for (const CorFormat format : {CorFormat::kJcz2, CorFormat::kLmc1}) {
    for (const CorReading& reading : AllCorReadings()) {
      SCOPED_TRACE(reading.Code());
      const std::string first = Temp("insitu_export_1.cor"), second = Temp("insitu_export_2.cor");
      ASSERT_TRUE(WriteCor(first, FromCorrection(correction, kLens, format, reading)).ok());
      const auto cor = ReadCor(first);
      ASSERT_TRUE(cor.ok());
      const std::string csv = ToCorrectionCsv(*cor, reading);
      const auto table = pattern::CorrectionTable::Parse(csv, "imported.csv");
      ASSERT_TRUE(table.ok()) << table.status().ToString();
      const auto named = CorReadingOfCsv(csv, "imported.csv");
      ASSERT_TRUE(named.ok() && named->has_value());
      ASSERT_EQ(**named, reading);
      ASSERT_TRUE(
          WriteCor(second, FromCorrection([&](double x, double y) { return table->OffsetAt(x, y); },
                                          kLens, format, **named))
              .ok());
      ASSERT_TRUE(Bytes(first) == Bytes(second)) << "the second export differs";
    }
  }
}

TEST(LmcCor, MalformedFilesAreNamed) {
  const double scale = 65536.0 / 110.0;
  const auto append = [](std::string* b, auto v) {
    b->append(reinterpret_cast<const char*>(&v), sizeof v);
  };
  const auto lmc1 = [&](double scale_value, int bad_entry, double bad_value) {
    std::string b = "LMC1COR_1.0";
    b.resize(24, '\0');
    for (int k = 0; k < 63; ++k) append(&b, k == 43 ? scale_value : 0.0);
    for (int n = 0; n < 2 * 4225; ++n) append(&b, n == bad_entry ? bad_value : 1.0);
    return b;
  };
  const std::string path = Temp("insitu_malformed.cor");
  const auto expect = [&](const std::string& bytes, const std::string& what) {
    Put(path, bytes);
    const auto r = ReadCor(path);
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_EQ(r.status().code(), StatusCode::kParseError);
    EXPECT_NE(r.status().message().find(path), std::string::npos) << r.status().message();
    EXPECT_NE(r.status().message().find(what), std::string::npos) << r.status().message();
  };
  expect("EZCAD_COR_9_9 and more bytes than a label", "not a .cor file");
  expect(lmc1(scale, 2 * 100 + 1, NAN), "entry 100 of 4225 holds an offset that is not a number");
  expect(lmc1(scale, 6, 40000.0), "entry 3 of 4225 holds an offset of 40000");
  expect(lmc1(NAN, -1, 0.0), "is not a lens field");
  expect(lmc1(0.0, -1, 0.0), "is not a lens field");
  expect(lmc1(scale, -1, 0.0).substr(0, 1000), "a LMC1COR_1.0 file needs");
  expect("JCZ", "too short");
  // A written table must be 65 x 65 and within the board's words.
  CorFile small;
  small.offsets.resize(10);
  EXPECT_EQ(WriteCor(path, small).code(), StatusCode::kInvalidArgument);
  CorFile huge = FromCorrection([](double, double) { return Vector2d(100.0, 0.0); }, 110.0,
                                CorFormat::kJcz2, DocumentedReading(false));
  EXPECT_EQ(WriteCor(path, huge).code(), StatusCode::kOutOfRange);
}

TEST(LmcCor, ReadingsParseAndNameThemselves) {
  const std::vector<CorReading> all = AllCorReadings();
  ASSERT_EQ(all.size(), 16u);
  EXPECT_EQ(all[0], CorReading{});
  for (const CorReading& r : all) {
    const auto back = ParseCorReading(r.Code());
    ASSERT_TRUE(back.ok()) << r.Code();
    EXPECT_EQ(*back, r);
  }
  EXPECT_EQ(CorReading{}.Name(), "pair (dx, dy), x-major, signs (+,+)");
  const auto partial = ParseCorReading("+-, dy-dx");
  ASSERT_TRUE(partial.ok());
  EXPECT_EQ(partial->Code(), "dy-dx,x-major,+-");
  for (const char* bad : {"", "dx-dy,dy-dx", "xy", "dy-dx,z-major", "+++"}) {
    const auto r = ParseCorReading(bad);
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << bad;
  }
  // A CSV's reading comment that does not parse is named with its line.
  const auto csv =
      CorReadingOfCsv("# from a .cor\n# reading: dz-dx\nx_mm,y_mm,dx_mm,dy_mm\n", "table.csv");
  ASSERT_FALSE(csv.ok());
  EXPECT_NE(csv.status().message().find("table.csv:2"), std::string::npos)
      << csv.status().message();
  const auto none = CorReadingOfCsv("x_mm,y_mm,dx_mm,dy_mm\n", "table.csv");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
}

}  // namespace
}  // namespace insitu::hw::lmc
