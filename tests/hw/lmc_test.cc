// The LMC backend against the protocol facts (docs/hardware.md): the reference list byte for
// byte, single commands, packets, .cor files in both formats, the correction upload, and
// marking through the board emulator on the simulated head compared with the same list run
// on the head directly; abort stops the laser.
#include "hw/lmc/lmc.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <random>
#include <sstream>
#include <thread>

#include "hw/lmc/sim_board.h"
#include "insitu/hw/cell.h"
#include "insitu/hw/lmc_capture.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/hw/sim_backend.h"
#include "insitu/sim/world.h"

namespace insitu::hw::lmc {
namespace {

// The golden list (docs/hardware.md, "LMC"; meerk40t's `lmc_rect`): a 10 mm square with
// corners 25 and 35 mm from the centre of a 110 mm lens, marked at 15 mm/s, full current,
// 20 kHz, laser on and off delays 100 us, polygon delay 100 us, 8 ms for the oscillator. The
// reference lists it up to the first mark; the rest of the square and the 300 us mark delay
// follow from the same rules.
constexpr char kGolden[] =
    "listReadyMark        0000 0000 0000 0000 0000\n"
    "listDelayTime        0320 0000 0000 0000 0000\n"
    "listWritePort        0001 0000 0000 0000 0000\n"
    "listJumpSpeed        04a7 0000 0000 0000 0000\n"
    "listQSwitchPeriod    03e8 0000 0000 0000 0000\n"
    "listMarkCurrent      0fff 0000 0000 0000 0000\n"
    "listMarkSpeed        0008 0000 0000 0000 0000\n"
    "listLaserOnDelay     0064 0000 0000 0000 0000\n"
    "listLaserOffDelay    0064 0000 0000 0000 0000\n"
    "listPolygonDelay     000a 0000 0000 0000 0000\n"
    "listJumpTo           d174 2e8b 0000 7331 0000\n"
    "listMarkTo           d174 45d1 0000 1746 0000\n";
constexpr char kRestOfTheSquare[] =
    "listMarkTo           ba2e 45d1 0000 1746 0000\n"
    "listMarkTo           ba2e 2e8b 0000 1746 0000\n"
    "listMarkTo           d174 2e8b 0000 1746 0000\n"
    "listDelayTime        001e 0000 0000 0000 0000\n";

GalvoList ReferenceSquare() {
  GalvoList l;
  l.jump_speed_mm_per_s = 2000.0;
  l.mark_speed_mm_per_s = 15.0;
  l.laser_power = 1.0;
  l.laser_frequency_khz = 20.0;
  l.laser_on_delay_us = 100.0;
  l.laser_off_delay_us = 100.0;
  l.mark_delay_us = 300.0;
  l.entries.push_back({GalvoListEntry::Kind::kJump, {35, -35, 0}});
  for (const auto& p : {Eigen::Vector3d(35, -25, 0), Eigen::Vector3d(25, -25, 0),
                        Eigen::Vector3d(25, -35, 0), Eigen::Vector3d(35, -35, 0)}) {
    l.entries.push_back({GalvoListEntry::Kind::kMark, p});
  }
  return l;
}

TEST(Lmc, TheReferenceListByteForByte) {
  BoardOptions o;  // 110 mm lens, the reference's defaults
  std::array<uint16_t, 2> at{0x8000, 0x8000};
  uint16_t z = 0x8000;
  const auto commands = EncodeList(ReferenceSquare(), o, &at, &z);
  ASSERT_TRUE(commands.ok()) << commands.status().ToString();
  EXPECT_EQ(FormatCommands(*commands), std::string(kGolden) + kRestOfTheSquare);
  EXPECT_EQ(at[0], 0xd174);
  EXPECT_EQ(at[1], 0x2e8b);

  // On the wire: one packet, the words little-endian, padded with end-of-list.
  const auto packets = Packets(*commands);
  ASSERT_EQ(packets.size(), 1u);
  ASSERT_EQ(packets[0].size(), 3072u);
  const uint8_t jump[12] = {0x01, 0x80, 0x74, 0xd1, 0x8b, 0x2e, 0x00, 0x00, 0x31, 0x73, 0, 0};
  EXPECT_TRUE(std::equal(jump, jump + 12, packets[0].begin() + 10 * 12));
  for (size_t k = commands->size(); k < 256; ++k) {
    EXPECT_EQ(packets[0][12 * k], 0x02);
    EXPECT_EQ(packets[0][12 * k + 1], 0x80);
    for (int b = 2; b < 12; ++b) ASSERT_EQ(packets[0][12 * k + b], 0);
  }
}

TEST(Lmc, SingleCommandsAndUnits) {
  const auto goto_centre = SingleCommand(kGotoXY, 0x8000, 0x8000);
  const std::vector<uint8_t> expected{0x0d, 0, 0x00, 0x80, 0x00, 0x80, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(goto_centre, expected);
  BoardOptions o;
  EXPECT_EQ(ToUnits(60.0, 0.0, o).status().code(), StatusCode::kOutOfRange);  // lens 110
  // Swap and flips move the axes as configured; FromUnits undoes ToUnits to a unit.
  o.swap_xy = true;
  o.flip_y = true;
  const auto u = ToUnits(10.0, 20.0, o);
  ASSERT_TRUE(u.ok());
  EXPECT_LT((*u)[0], 0x8000);  // -20 mm on the board's first axis
  EXPECT_GT((*u)[1], 0x8000);
  const auto back = FromUnits((*u)[0], (*u)[1], o);
  EXPECT_NEAR(back[0], 10.0, 110.0 / 65536);
  EXPECT_NEAR(back[1], 20.0, 110.0 / 65536);
  // A head without a focus shifter refuses z.
  GalvoList l = ReferenceSquare();
  l.entries[1].to_in_galvo.z() = 1.0;
  std::array<uint16_t, 2> at{0x8000, 0x8000};
  uint16_t z = 0;
  EXPECT_EQ(EncodeList(l, BoardOptions{}, &at, &z).status().code(), StatusCode::kOutOfRange);
}

// A triggered sweep is one light list: per line a jump to its end nearer the head, the settle
// as a list delay, the trigger bit raised for the pulse beside the pointer's bit and lowered,
// then passes back and forth for the dwell (12 ms at 2000 mm/s: 24 mm over a 20 mm line, so a
// full pass and 4 mm back), the next line from its end nearer to where that left the head.
TEST(Lmc, ATriggeredSweepRaisesTheTriggerBitOncePerLine) {
  BoardOptions o;
  o.trigger_port = 0x0002;
  TriggeredSweep sweep;
  sweep.lines = {{{-10, 0, 0}, {10, 0, 0}}, {{-10, 1, 0}, {10, 1, 0}}};
  sweep.speed_mm_per_s = 2000.0;
  sweep.settle_s = 0.005;
  sweep.dwell_s = 0.012;
  const auto units = [&](double x, double y) { return *ToUnits(x, y, o); };
  std::array<uint16_t, 2> at = units(-30, 0);
  uint16_t z = 0;
  const auto list = EncodeTriggeredSweep(sweep, o, &at, &z);
  ASSERT_TRUE(list.ok()) << list.status().ToString();
  const std::string text = FormatCommands(*list);
  // The header: the pointer's port, no laser current.
  EXPECT_NE(text.find("listWritePort        0100 0000"), std::string::npos) << text;
  EXPECT_NE(text.find("listMarkCurrent      0000 0000"), std::string::npos) << text;
  // After the header: line 0 from x = -10 (nearer x = -30), line 1 from x = +10 (nearer +6).
  const std::vector<Command> body(list->begin() + 10, list->end());
  const auto jump = [](const std::array<uint16_t, 2>& u) {
    return std::make_pair(static_cast<uint16_t>(kJumpTo), u);
  };
  const std::vector<std::pair<uint16_t, std::array<uint16_t, 2>>> expected{
      jump(units(-10, 0)), {kDelayTime, {500, 0}},   {kWritePortList, {0x0102, 0}},
      {kDelayTime, {10, 0}}, {kWritePortList, {0x0100, 0}}, jump(units(10, 0)),
      jump(units(6, 0)),   jump(units(10, 1)),     {kDelayTime, {500, 0}},
      {kWritePortList, {0x0102, 0}}, {kDelayTime, {10, 0}}, {kWritePortList, {0x0100, 0}},
      jump(units(-10, 1)), jump(units(-6, 1))};
  ASSERT_EQ(body.size(), expected.size()) << text;
  for (size_t k = 0; k < body.size(); ++k) {
    EXPECT_EQ(body[k][0], expected[k].first) << "command " << k << "\n" << text;
    EXPECT_NEAR(body[k][1], expected[k].second[0], 1) << "command " << k << "\n" << text;
    if (body[k][0] == kJumpTo) {
      EXPECT_NEAR(body[k][2], expected[k].second[1], 1) << k;
    }
  }
  // A board without the output, a settle longer than the list delay holds: refused.
  EXPECT_EQ(EncodeTriggeredSweep(sweep, BoardOptions{}, &at, &z).status().code(),
            StatusCode::kFailedPrecondition);
  sweep.settle_s = 0.7;
  EXPECT_EQ(EncodeTriggeredSweep(sweep, o, &at, &z).status().code(), StatusCode::kOutOfRange);
  // The output must be one bit of its own, its pulse short (the pointer waits for it).
  o.trigger_pulse_us = 5000;
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  o.trigger_pulse_us = 100;
  o.trigger_port = 0x0003;
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  o.trigger_port = 0x0100;  // the pointer's
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
}

TEST(Lmc, CorFilesRoundTripInBothFormats) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> offset(-3000, 3000);
  const std::filesystem::path dir = std::filesystem::temp_directory_path();
  for (const CorFormat format : {CorFormat::kJcz2, CorFormat::kLmc1}) {
    CorFile cor;
    cor.format = format;
    cor.scale = 65536.0 / 163.0;
    for (int n = 0; n < 65 * 65; ++n) {
      cor.offsets.push_back({static_cast<double>(offset(rng)), static_cast<double>(offset(rng))});
    }
    const std::string path =
        (dir / (format == CorFormat::kJcz2 ? "insitu_test_jcz.cor" : "insitu_test_lmc1.cor"))
            .string();
    ASSERT_TRUE(WriteCor(path, cor).ok());
    if (format == CorFormat::kJcz2) {
      EXPECT_EQ(std::filesystem::file_size(path), 33840u);
    }
    const auto back = ReadCor(path);
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(back->format, format);
    EXPECT_DOUBLE_EQ(back->scale, cor.scale);
    EXPECT_NEAR(back->lens_mm(), 163.0, 1e-9);
    ASSERT_EQ(back->offsets.size(), cor.offsets.size());
    for (size_t n = 0; n < cor.offsets.size(); ++n) ASSERT_EQ(back->offsets[n], cor.offsets[n]);
  }
  // Bad files are named, with what is wrong.
  const std::string junk = (dir / "insitu_test_junk.cor").string();
  std::FILE* f = std::fopen(junk.c_str(), "wb");
  std::fputs("JCZ_COR_2_1 but far too short", f);
  std::fclose(f);
  const auto bad = ReadCor(junk);
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_NE(bad.status().message().find("33840"), std::string::npos) << bad.status().message();
  EXPECT_EQ(ReadCor((dir / "insitu_no_such.cor").string()).status().code(), StatusCode::kNotFound);
}

// A field correction exported to .cor comes back through insitu's correction CSV unchanged (to
// the unit rounding of the JCZ format).
TEST(Lmc, CorrectionExportAndImport) {
  const auto bulge = [](double x, double y) {
    return Eigen::Vector2d(2e-6 * x * (x * x + y * y), 2e-6 * y * (x * x + y * y));
  };
  const CorReading reading = DocumentedReading(false);
  const CorFile cor = FromCorrection(bulge, 163.0, CorFormat::kJcz2, reading);
  const std::string path = (std::filesystem::temp_directory_path() / "insitu_bulge.cor").string();
  ASSERT_TRUE(WriteCor(path, cor).ok());
  const auto back = ReadCor(path);
  ASSERT_TRUE(back.ok());
  const std::string csv = ToCorrectionCsv(*back, reading);
  // Node (64, 64) is the field's corner: 81.5 mm on both axes. Stored as the documented
  // convention has it: the error the board subtracts, the negated offset.
  const Eigen::Vector2d corner = back->NodeMm(64, 64);
  EXPECT_NEAR(corner.x(), 81.5, 1e-9);
  const auto& o = back->offsets[64 * 65 + 64];
  const double unit_mm = 163.0 / 65536;
  EXPECT_NEAR(-o[0] / back->scale, bulge(81.5, 81.5).x(), 0.5 * unit_mm);
  EXPECT_NEAR(back->OffsetMm(64, 64, reading).y(), bulge(81.5, 81.5).y(), 0.5 * unit_mm);
  EXPECT_NE(csv.find("x_mm,y_mm,dx_mm,dy_mm"), std::string::npos);
}

TEST(Lmc, TheCorrectionUploadInSignMagnitude) {
  BoardCorrection table;
  for (int n = 0; n < 65 * 65; ++n) table.offsets.push_back({n % 7 - 3, -(n % 5)});
  const auto upload = CorrectionUpload(table);
  ASSERT_TRUE(upload.ok());
  ASSERT_EQ(upload->size(), 1u + 4225u);
  auto world = std::make_shared<sim::SimWorld>(sim::WorldOptions{});
  SimBoard board(world, BoardOptions{});
  ASSERT_TRUE(UploadCorrection(board, table).ok());
  EXPECT_EQ(board.log().single_commands, 4226);  // one reply read: WriteCorLine is not answered
  EXPECT_EQ(board.log().correction, table.offsets);
  // A machine whose board is to get a .cor file that is not there does not come up.
  MachineConfig config;
  config.scanner = "lmc";
  config.lmc.transport = "sim_board";
  config.lmc.correction_file = "/nonexistent/field.cor";
  const auto machine = CreateMachine(config);
  EXPECT_EQ(machine.status().code(), StatusCode::kNotFound);
  EXPECT_NE(machine.status().message().find("field.cor"), std::string::npos);
  table.offsets[3] = {40000, 0};
  EXPECT_EQ(CorrectionUpload(table).status().code(), StatusCode::kOutOfRange);
}

// The simulated head's field is +-70 mm: a 163 mm lens covers it (2.5 um per unit); the board
// drives the head's dynamic focus through its Z word, 1 um per unit.
BoardOptions SimHeadBoard() {
  BoardOptions o;
  o.lens_mm = 163.0;
  o.focus = Focus::kDaZWord;
  o.z_units_per_mm = 1000.0;
  o.focus_range_mm = 25.0;
  o.poll_ms = 1;
  return o;
}

// The scanner on a board opened as the machine opens it (StartUp: serial, version, Reset, a blank
// correction table, the modes).
std::unique_ptr<Scanner> Opened(std::unique_ptr<SimBoard> board, const BoardOptions& o) {
  auto opened = OpenScanner(std::move(board), o);
  EXPECT_TRUE(opened.ok()) << opened.status().ToString();
  return opened.ok() ? std::move(*opened) : nullptr;
}

GalvoList Hatch(double z_mm) {
  GalvoList l;
  l.laser_on_delay_us = 100;
  l.laser_off_delay_us = 200;
  l.jump_delay_us = 300;
  l.mark_delay_us = 250;
  for (int k = 0; k < 21; ++k) {  // a 4 x 4 mm square hatched every 0.2 mm
    const double y = -2.0 + 0.2 * k;
    l.entries.push_back({GalvoListEntry::Kind::kJump, {-2.0, y, z_mm}});
    l.entries.push_back({GalvoListEntry::Kind::kMark, {2.0, y, z_mm}});
  }
  return l;
}

TEST(Lmc, MarkingThroughTheBoardMatchesTheHeadItself) {
  for (const double z : {0.0, 2.0}) {  // in focus on the plate, and 2 mm above it
    sim::WorldOptions w;
    w.part.kind = "none";
    auto direct_world = std::make_shared<sim::SimWorld>(w);
    auto board_world = std::make_shared<sim::SimWorld>(w);
    Machine direct = MakeSimMachine(direct_world);
    auto board = std::make_unique<SimBoard>(board_world, SimHeadBoard());
    const SimBoard* log = board.get();
    auto lmc = Opened(std::move(board), SimHeadBoard());
    ASSERT_NE(lmc, nullptr);
    EXPECT_EQ(lmc->ExecuteList(Hatch(z)).code(), StatusCode::kFailedPrecondition);  // not armed
    ASSERT_TRUE(direct.scanner->Arm().ok());
    ASSERT_TRUE(lmc->Arm().ok());
    ASSERT_TRUE(direct.scanner->ExecuteList(Hatch(z)).ok());
    const Status ran = lmc->ExecuteList(Hatch(z));
    ASSERT_TRUE(ran.ok()) << ran.ToString();
    ASSERT_TRUE(lmc->Disarm().ok());
    EXPECT_FALSE(log->log().laser_enabled);
    EXPECT_EQ(log->log().lists_executed, 1);
    EXPECT_EQ(log->log().end_of_lists, 1);  // the list ran to its end
    EXPECT_EQ(log->log().ports, 0);         // the list's ports off again after it
    EXPECT_TRUE(log->log().rejected.empty()) << log->log().rejected.front();

    const auto& a = direct_world->mark_pulses();
    const auto& b = board_world->mark_pulses();
    ASSERT_GT(a.size(), 1000u);
    // The same marks: speed words are whole units per ms (1000 mm/s runs at 999.85 mm/s) and
    // points whole units (2.5 um), so the pulse counts differ by a few per thousand at most.
    const double ratio = static_cast<double>(b.size()) / a.size();
    EXPECT_NEAR(ratio, 1.0, 0.005) << a.size() << " vs " << b.size();
    // Every pulse lands where the head itself puts it: the worst distance from a hatch line
    // (where the mirrors' lag bends the line ends) is the direct run's to within the unit
    // quantisation (2.5 um), at the asked focus.
    const auto worst_offset = [](const std::vector<sim::MarkPulse>& pulses) {
      double worst = 0.0;
      for (const sim::MarkPulse& p : pulses) {
        const double line_y = -2.0 + 0.2 * std::round((p.point_in_world.y() + 2.0) / 0.2);
        worst = std::max(worst, std::abs(p.point_in_world.y() - line_y));
      }
      return worst;
    };
    for (const sim::MarkPulse& p : b) {
      ASSERT_NEAR(p.defocus_mm, z, 0.01);
      ASSERT_GT(p.point_in_world.x(), -2.05);
      ASSERT_LT(p.point_in_world.x(), 2.05);
    }
    const double worst_board = worst_offset(b), worst_direct = worst_offset(a);
    EXPECT_NEAR(worst_board, worst_direct, 0.0025);
    std::printf(
        "z = %.1f mm: %zu pulses through the board, %zu direct; worst line offset %.2f um "
        "(direct %.2f um)\n",
        z, b.size(), a.size(), worst_board * 1e3, worst_direct * 1e3);
  }
}

// A list longer than the board takes before it starts streams in as the board reports READY,
// and marks as the head does.
TEST(Lmc, LongListsStreamInPackets) {
  sim::WorldOptions w;
  w.part.kind = "none";
  auto direct_world = std::make_shared<sim::SimWorld>(w);
  auto board_world = std::make_shared<sim::SimWorld>(w);
  BoardOptions o = SimHeadBoard();
  o.packets_before_start = 1;
  auto board = std::make_unique<SimBoard>(board_world, o);
  const SimBoard* log = board.get();
  auto lmc = Opened(std::move(board), o);
  ASSERT_NE(lmc, nullptr);
  GalvoList l = Hatch(0.0);
  l.entries.clear();
  // 180 lines: a jump, a mark and the mark delay each, after the list's 12 parameters: 552
  // commands, 3 packets.
  for (int k = 0; k < 180; ++k) {
    const double y = -18.0 + 0.2 * k;
    l.entries.push_back({GalvoListEntry::Kind::kJump, {-2.0, y, 0.0}});
    l.entries.push_back({GalvoListEntry::Kind::kMark, {2.0, y, 0.0}});
  }
  Machine direct = MakeSimMachine(direct_world);
  ASSERT_TRUE(direct.scanner->Arm().ok());
  ASSERT_TRUE(lmc->Arm().ok());
  ASSERT_TRUE(direct.scanner->ExecuteList(l).ok());
  const Status ran = lmc->ExecuteList(l);
  ASSERT_TRUE(ran.ok()) << ran.ToString();
  EXPECT_EQ(log->log().packets, 3);
  const double ratio =
      static_cast<double>(board_world->mark_pulses().size()) / direct_world->mark_pulses().size();
  // A packet boundary inside a mark sequence restarts the emulated head's laser-on delay (a
  // real board streams on): a few pulses of ~18000 at most.
  EXPECT_NEAR(ratio, 1.0, 0.005) << board_world->mark_pulses().size();
}

// The board runs a list until it executes an end-of-list. Lists of every length around a
// packet's 256 commands go out with exactly one before their padding (a list filling its last
// packet gets a packet for it), and the emulator, sent them as the scanner sends a list, runs
// each to that end; without it the board stays busy, waiting for the rest of the list.
uint16_t StatusWord(Transport& board, uint16_t op, uint16_t p1 = 0) {
  const auto bytes = SingleCommand(op, p1);
  EXPECT_TRUE(board.Write(bytes.data(), bytes.size()).ok());
  uint8_t reply[kReplyBytes] = {};
  EXPECT_TRUE(board.Read(reply, sizeof reply).ok());
  return static_cast<uint16_t>(reply[6] | (reply[7] << 8));
}

// ResetList, each packet with SetEndOfList, ExecuteList after the first; then polls until the
// board is not busy. False if it still is after `wait_s`.
bool SendAndWait(Transport& board, const std::vector<std::vector<uint8_t>>& packets,
                 double wait_s) {
  StatusWord(board, kResetList);
  for (size_t i = 0; i < packets.size(); ++i) {
    EXPECT_TRUE(board.Write(packets[i].data(), packets[i].size()).ok());
    StatusWord(board, kSetEndOfList);
    if (i == 0) StatusWord(board, kExecuteList);
  }
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < wait_s) {
    if (!(StatusWord(board, kGetVersion) & kStatusBusy)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return false;
}

TEST(Lmc, EveryListEndsOnceWhateverItsLength) {
  sim::WorldOptions w;
  w.part.kind = "none";
  for (size_t n : {1u, 255u, 256u, 257u, 511u, 512u}) {
    SCOPED_TRACE("list of " + std::to_string(n) + " commands");
    std::vector<Command> list;
    for (size_t k = 0; k < n; ++k) {  // jumps back and forth, 1 mm apart
      list.push_back(
          {kJumpTo, static_cast<uint16_t>(k % 2 ? 0x8200 : 0x8000), 0x8000, 0, 0x200, 0});
    }
    const auto packets = Packets(list);
    ASSERT_EQ(packets.size(), n / kPacketCommands + 1);
    // Decoded, the list ends where its commands do; everything after is padding.
    std::vector<Command> decoded;
    for (const auto& p : packets) {
      for (size_t k = 0; k < kPacketCommands; ++k) decoded.push_back(DecodeCommand(&p[k * 12]));
    }
    const auto end = std::find_if(decoded.begin(), decoded.end(),
                                  [](const Command& c) { return c[0] == kEndOfList; });
    ASSERT_NE(end, decoded.end());
    EXPECT_EQ(static_cast<size_t>(end - decoded.begin()), n);
    EXPECT_TRUE(
        std::all_of(end, decoded.end(), [](const Command& c) { return c[0] == kEndOfList; }));

    SimBoard board(std::make_shared<sim::SimWorld>(w), SimHeadBoard());
    ASSERT_TRUE(StartUp(board, SimHeadBoard(), {}).ok());
    ASSERT_TRUE(SendAndWait(board, packets, 5.0));
    EXPECT_EQ(board.log().lists_executed, 1);
    EXPECT_EQ(board.log().end_of_lists, 1);
  }
  // A packet of 256 commands and no end: the board waits for the rest, busy, until stopped.
  std::vector<uint8_t> unended;
  for (size_t k = 0; k < kPacketCommands; ++k) {
    for (uint16_t word : {static_cast<uint16_t>(kJumpTo), uint16_t{0x8000}, uint16_t{0x8000},
                          uint16_t{0}, uint16_t{0}, uint16_t{0}}) {
      unended.push_back(static_cast<uint8_t>(word & 0xFF));
      unended.push_back(static_cast<uint8_t>(word >> 8));
    }
  }
  SimBoard board(std::make_shared<sim::SimWorld>(w), SimHeadBoard());
  ASSERT_TRUE(StartUp(board, SimHeadBoard(), {}).ok());
  EXPECT_FALSE(SendAndWait(board, {unended}, 0.3));
  EXPECT_GE(board.log().starved, 1);
  EXPECT_EQ(board.log().end_of_lists, 0);
  EXPECT_FALSE(StatusWord(board, kStopExecute) & kStatusBusy);
}

// GotoXY carries the distance from where the head is, as a list's JumpTo does (x, y, angle 0,
// distance): 10 mm on a 163 mm lens is 10 x 65536 / 163 = 4020.6 units, truncated.
TEST(Lmc, GotoCarriesItsDistance) {
  sim::WorldOptions w;
  w.part.kind = "none";
  auto board = std::make_unique<SimBoard>(std::make_shared<sim::SimWorld>(w), SimHeadBoard());
  const SimBoard* log = board.get();
  auto lmc = Opened(std::move(board), SimHeadBoard());
  ASSERT_NE(lmc, nullptr);
  ASSERT_TRUE(lmc->StartPointerLine({10.0, 0.0, 0.0}, {20.0, 0.0, 0.0}, 100.0).ok());
  ASSERT_TRUE(lmc->StopPointer().ok());
  EXPECT_NEAR(log->log().last_goto_distance, 10.0 * 65536.0 / 163.0, 1.0);  // a unit's floor
}

TEST(Lmc, AbortStopsTheBoardAndTheLaser) {
  sim::WorldOptions w;
  w.part.kind = "none";
  w.real_time_factor = 1.0;  // the board runs its list in real time
  auto world = std::make_shared<sim::SimWorld>(w);
  auto board = std::make_unique<SimBoard>(world, SimHeadBoard());
  const SimBoard* log = board.get();
  auto lmc = Opened(std::move(board), SimHeadBoard());
  ASSERT_NE(lmc, nullptr);
  GalvoList l = Hatch(0.0);
  l.mark_speed_mm_per_s = 100.0;  // 84 mm of marks: 0.84 s
  ASSERT_TRUE(lmc->Arm().ok());
  std::atomic<bool> abort{false};
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    abort = true;
  });
  ListControl control;
  control.abort = &abort;
  const auto t0 = std::chrono::steady_clock::now();
  const Status s = lmc->ExecuteList(l, control);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  stopper.join();
  EXPECT_EQ(s.code(), StatusCode::kCancelled) << s.ToString();
  EXPECT_LT(took, 0.6);  // aborted at 0.3 s, not run to its 0.84 s end
  EXPECT_FALSE(lmc->armed());
  EXPECT_FALSE(log->log().laser_enabled);
  EXPECT_GE(log->log().stops, 1);
  // Then the flush: an empty list executed to its end, the ports off.
  EXPECT_EQ(log->log().end_of_lists, 1);
  EXPECT_EQ(log->log().ports, 0);
  const sim::ListAbortTruth& a = world->last_list_abort();
  ASSERT_TRUE(a.aborted);
  double last = 0.0;
  for (const auto& p : world->mark_pulses()) last = std::max(last, p.t_s);
  EXPECT_LE(last, a.seen_at_s + 1e-12);
}

// Records every command a transport is sent (for the start-up's order).
class Recording : public Transport {
 public:
  explicit Recording(Transport* inner) : inner_(inner) {}
  Status Write(const uint8_t* data, size_t size) override {
    if (size == kCommandBytes) sent.push_back(DecodeCommand(data));
    return inner_->Write(data, size);
  }
  Status Read(uint8_t* data, size_t size) override { return inner_->Read(data, size); }
  std::string Describe() const override { return inner_->Describe(); }
  std::vector<Command> sent;

 private:
  Transport* inner_;
};

// The board opens as EzCad2 opens it (the start-up open drivers replay from its captures):
// serial and version read, Reset, the correction table (blank without one), the laser output
// enabled for the modes, standby, first pulse killer, PWM, the oscillator closed, the FPK and
// on-the-fly parameters, Z and the analog port; then insitu disables the output until a job
// arms it. The emulator counts the board started only after all of it.
TEST(Lmc, TheBoardStartsAsEzCadStartsIt) {
  sim::WorldOptions w;
  w.part.kind = "none";
  SimBoard board(std::make_shared<sim::SimWorld>(w), SimHeadBoard());
  EXPECT_FALSE(board.log().started);
  Recording wire(&board);
  const auto id = StartUp(wire, SimHeadBoard(), {});
  ASSERT_TRUE(id.ok()) << id.status().ToString();
  EXPECT_EQ(id->serial, "0x0e2c202611270001");  // the emulator's four serial words
  EXPECT_EQ(id->version[0], 0x0001);
  const std::vector<Command> expected = {{kGetSerialNo, 0, 0, 0, 0, 0},
                                         {kGetVersion, 0, 0, 0, 0, 0},
                                         {kReset, 0, 0, 0, 0, 0},
                                         {kWriteCorTable, 0, 0, 0, 0, 0},
                                         {kEnableLaser, 0, 0, 0, 0, 0},
                                         {kSetControlMode, 0, 0, 0, 0, 0},
                                         {kSetLaserMode, 1, 0, 0, 0, 0},
                                         {kSetDelayMode, 1, 0, 0, 0, 0},
                                         {kSetTiming, 1, 0, 0, 0, 0},
                                         {kSetStandby, 2000, 20, 0, 0, 0},
                                         {kSetFirstPulseKiller, 200, 0, 0, 0, 0},
                                         {kSetPwmHalfPeriod, 125, 0, 0, 0, 0},
                                         {kSetPwmPulseWidth, 125, 0, 0, 0, 0},
                                         {kFiberSetMo, 0, 0, 0, 0, 0},
                                         {kSetFpkParam2, 0xFFB, 1, 409, 100, 0},
                                         {kSetFlyRes, 0, 99, 1000, 25, 0},
                                         {kEnableZ, 0, 0, 0, 0, 0},
                                         {kWriteAnalogPort1, 0x7FF, 0, 0, 0, 0},
                                         {kEnableZ, 0, 0, 0, 0, 0},
                                         {kDisableLaser, 0, 0, 0, 0, 0}};
  EXPECT_EQ(FormatCommands(wire.sent), FormatCommands(expected));
  const SimBoardLog log = board.log();
  EXPECT_TRUE(log.started);
  EXPECT_TRUE(log.correction_blank);
  EXPECT_FALSE(log.laser_enabled);  // off until a job arms it
  EXPECT_TRUE(log.rejected.empty());

  // The job's values go out instead of EzCad's; a table goes up whole.
  BoardOptions o = SimHeadBoard();
  o.startup.standby_1 = 1000;
  o.startup.fpk2 = {0x0FFB, 1, 300, 50};
  BoardCorrection table;
  table.offsets.assign(65 * 65, {3, -4});
  SimBoard second(std::make_shared<sim::SimWorld>(w), o);
  Recording wire2(&second);
  ASSERT_TRUE(StartUp(wire2, o, table).ok());
  EXPECT_EQ(second.log().correction.size(), 65u * 65u);
  EXPECT_FALSE(second.log().correction_blank);
  const auto find = [&](uint16_t op) {
    return *std::find_if(wire2.sent.begin(), wire2.sent.end(),
                         [&](const Command& c) { return c[0] == op; });
  };
  EXPECT_EQ(find(kSetStandby)[1], 1000);
  EXPECT_EQ(find(kSetFpkParam2)[3], 300);
  EXPECT_EQ(find(kSetFpkParam2)[4], 50);
  EXPECT_EQ(find(kWriteCorTable)[1], 1);
}

// A transport that fails the first write of one opcode (a cable pulled mid start-up).
class FailOnce : public Transport {
 public:
  FailOnce(Transport* inner, uint16_t op) : inner_(inner), op_(op) {}
  Status Write(const uint8_t* data, size_t size) override {
    if (!failed_ && size == kCommandBytes && DecodeCommand(data)[0] == op_) {
      failed_ = true;
      return Status(StatusCode::kDeviceError, "usb: transfer timed out");
    }
    return inner_->Write(data, size);
  }
  Status Read(uint8_t* data, size_t size) override { return inner_->Read(data, size); }
  std::string Describe() const override { return inner_->Describe(); }

 private:
  Transport* inner_;
  uint16_t op_;
  bool failed_ = false;
};

// A start-up that fails after it enabled the laser output leaves the output disabled, and a
// Reset returns the emulated board to power-up: no list runs until it is started again.
TEST(Lmc, AFailedStartUpLeavesTheLaserOff) {
  sim::WorldOptions w;
  w.part.kind = "none";
  SimBoard board(std::make_shared<sim::SimWorld>(w), SimHeadBoard());
  FailOnce wire(&board, kSetTiming);
  const auto id = StartUp(wire, SimHeadBoard(), {});
  ASSERT_FALSE(id.ok());
  EXPECT_EQ(id.status().code(), StatusCode::kDeviceError);
  EXPECT_FALSE(board.log().laser_enabled);
  EXPECT_FALSE(board.log().mo_open);
  EXPECT_FALSE(board.log().started);
  ASSERT_TRUE(StartUp(board, SimHeadBoard(), {}).ok());  // the second try completes
  EXPECT_TRUE(board.log().started);
  StatusWord(board, kReset);
  EXPECT_FALSE(board.log().started);
  EXPECT_EQ(board.log().resets, 3);  // each start-up's and this one
}

// A board fresh from power-up that was never started runs no list: the emulator refuses it
// and says so, as the tests' strict board must.
TEST(Lmc, ABoardNeverStartedRunsNoList) {
  sim::WorldOptions w;
  w.part.kind = "none";
  auto world = std::make_shared<sim::SimWorld>(w);
  auto board = std::make_unique<SimBoard>(world, SimHeadBoard());
  const SimBoard* log = board.get();
  auto lmc = MakeScanner(std::move(board), SimHeadBoard());  // no StartUp
  ASSERT_TRUE(lmc->Arm().ok());
  (void)lmc->ExecuteList(Hatch(0.0));
  EXPECT_TRUE(world->mark_pulses().empty());
  ASSERT_FALSE(log->log().rejected.empty());
  EXPECT_NE(log->log().rejected.front().find("start-up"), std::string::npos)
      << log->log().rejected.front();
  EXPECT_EQ(log->log().lists_executed, 0);
}

// The list words of each source type (docs/hardware.md, "LMC"): a fibre source's Q-switch
// period (50 ns units) and current; a MOPA's pulse width before them; a CO2 or UV source's
// pulse period (100 ns units), first pulse killer and power ratio (200 x % / kHz), a UV's
// power inverted where its driver takes it so. Settings that mean nothing to a source are
// refused by name.
TEST(Lmc, EachSourceSendsItsOwnLaserWords) {
  const auto words = [](const BoardOptions& o, double power) {
    GalvoList l = ReferenceSquare();  // 20 kHz
    l.laser_power = power;
    std::array<uint16_t, 2> at{0x8000, 0x8000};
    uint16_t z = 0x8000;
    auto commands = EncodeList(l, o, &at, &z);
    EXPECT_TRUE(commands.ok()) << commands.status().ToString();
    std::map<uint16_t, Command> by_op;
    for (const Command& c : commands.ok() ? *commands : std::vector<Command>{}) by_op[c[0]] = c;
    return by_op;
  };
  BoardOptions fiber;
  auto f = words(fiber, 1.0);
  EXPECT_EQ(f[kQSwitchPeriod][1], 1000);  // 20000 / 20 kHz
  EXPECT_EQ(f[kMarkCurrent][1], 0xFFF);
  for (uint16_t op : {kMarkFreq, kMarkPowerRatio, kSetCo2Fpk, kFiberPulseWidth}) {
    EXPECT_EQ(f.count(op), 0u) << std::hex << op;
  }
  BoardOptions mopa;
  mopa.source = Source::kMopa;
  mopa.pulse_width_ns = 200;
  auto m = words(mopa, 0.5);
  EXPECT_EQ(m[kFiberPulseWidth][1], 200);
  EXPECT_EQ(m[kMarkCurrent][1], 2048);  // round(0.5 x 4095)
  BoardOptions co2;
  co2.source = Source::kCo2;
  auto c = words(co2, 1.0);
  EXPECT_EQ(c[kMarkFreq][1], 500);   // 10000 / 20 kHz
  EXPECT_EQ(c[kSetCo2Fpk][1], 100);  // 2000 / 20 kHz, twice
  EXPECT_EQ(c[kSetCo2Fpk][2], 100);
  EXPECT_EQ(c[kMarkPowerRatio][1], 1000);  // 200 x 100 % / 20 kHz
  EXPECT_EQ(c.count(kMarkCurrent) + c.count(kQSwitchPeriod), 0u);
  BoardOptions uv;
  uv.source = Source::kUv;
  uv.power_invert = true;
  EXPECT_EQ(words(uv, 0.3)[kMarkPowerRatio][1], 700);  // 200 x (100 - 30) % / 20 kHz

  const auto refused = [](const std::function<void(BoardOptions&)>& set, const char* field) {
    BoardOptions o;
    set(o);
    const Status st = o.Validate();
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << field;
    EXPECT_NE(st.message().find(field), std::string::npos) << st.message();
  };
  refused([](BoardOptions& o) { o.pulse_width_ns = 100; }, "pulse_width_ns");    // a fibre source
  refused([](BoardOptions& o) { o.source = Source::kMopa; }, "pulse_width_ns");  // none given
  refused([](BoardOptions& o) { o.source = Source::kCo2, o.power_invert = true; }, "power_invert");
  GalvoList fast = ReferenceSquare();
  fast.laser_frequency_khz = 15000.0;  // a fibre's Q-switch word holds it, a CO2's period not
  std::array<uint16_t, 2> at{0x8000, 0x8000};
  uint16_t z = 0;
  EXPECT_TRUE(EncodeList(fast, fiber, &at, &z).ok());
  EXPECT_EQ(EncodeList(fast, co2, &at, &z).status().code(), StatusCode::kInvalidArgument);
}

// The emulator reads each source's words back: the same hatch through a CO2 board and a fibre
// board marks the same pulses (rate and power agree to a word's rounding).
TEST(Lmc, TheEmulatorMarksWhatEachSourceWasSent) {
  std::vector<size_t> counts;
  std::vector<double> diameters;
  const std::vector<Source> sources = {Source::kFiber, Source::kCo2, Source::kUv};
  for (Source source : sources) {
    sim::WorldOptions w;
    w.part.kind = "none";
    auto world = std::make_shared<sim::SimWorld>(w);
    BoardOptions o = SimHeadBoard();
    o.source = source;
    auto lmc = Opened(std::make_unique<SimBoard>(world, o), o);
    ASSERT_NE(lmc, nullptr);
    ASSERT_TRUE(lmc->Arm().ok());
    GalvoList l = Hatch(0.0);
    l.laser_frequency_khz = 20.0;
    l.laser_power = 0.6;
    ASSERT_TRUE(lmc->ExecuteList(l).ok());
    counts.push_back(world->mark_pulses().size());
    double sum = 0;
    for (const auto& p : world->mark_pulses()) sum += p.diameter_mm;
    diameters.push_back(sum / std::max<size_t>(1, world->mark_pulses().size()));
  }
  ASSERT_GT(counts[0], 1000u);
  for (size_t i = 1; i < counts.size(); ++i) {
    EXPECT_EQ(counts[i], counts[0]) << SourceName(sources[i]);
    // The power ratio word is whole: 200 x 60 / 20 = 600 exactly; the current 0.6 x 4095 =
    // 2457 of 4095: 0.0001 apart, far under a crater's change.
    EXPECT_NEAR(diameters[i], diameters[0], 1e-4 * diameters[0]);
  }
}

// A parameter applies where it stands in the list: a hatch whose second half follows a higher
// current marks wider craters there, and the first half keeps its own.
TEST(Lmc, ParametersApplyWhereTheyStandInTheList) {
  sim::WorldOptions w;
  w.part.kind = "none";
  auto world = std::make_shared<sim::SimWorld>(w);
  const BoardOptions o = SimHeadBoard();
  SimBoard board(world, o);
  ASSERT_TRUE(StartUp(board, o, {}).ok());
  StatusWord(board, kEnableLaser);
  StatusWord(board, kFiberSetMo, 1);
  const auto at = [&](double x, double y) { return *ToUnits(x, y, o); };
  std::vector<Command> list = {{kJumpSpeed, 400, 0, 0, 0, 0},
                               {kMarkSpeed, 400, 0, 0, 0, 0},
                               {kQSwitchPeriod, 1000, 0, 0, 0, 0},
                               {kMarkCurrent, 0x600, 0, 0, 0, 0}};
  for (int half = 0; half < 2; ++half) {
    if (half == 1) list.push_back({kMarkCurrent, 0xFFF, 0, 0, 0, 0});
    for (int k = 0; k < 5; ++k) {
      const double y = (half == 0 ? -2.0 : 1.0) + 0.2 * k;
      const auto a = at(-2.0, y), b = at(2.0, y);
      list.push_back({kJumpTo, a[0], a[1], 0, 0, 0});
      list.push_back({kMarkTo, b[0], b[1], 0, 0, 0});
    }
  }
  ASSERT_TRUE(SendAndWait(board, Packets(list), 5.0));
  double low = 0, high = 0;
  int n_low = 0, n_high = 0;
  for (const auto& p : world->mark_pulses()) {
    (p.point_in_world.y() < 0 ? low : high) += p.diameter_mm;
    ++(p.point_in_world.y() < 0 ? n_low : n_high);
  }
  ASSERT_GT(n_low, 100);
  ASSERT_GT(n_high, 100);
  EXPECT_LT(low / n_low, 0.95 * (high / n_high));  // the fluence's log: wider at full current
  EXPECT_TRUE(board.log().rejected.empty());
}

// A board that scripts its status: busy with the list (not ready for the next packet) for
// `busy_s` after ExecuteList, then ready, then idle `busy_s` after the last packet.
class BusyBoard : public Transport {
 public:
  explicit BusyBoard(double busy_s) : busy_s_(busy_s) {}
  Status Write(const uint8_t* data, size_t size) override {
    if (size == kPacketBytes) {
      ++packets_;
      last_packet_ = Now();
      return Status::Ok();
    }
    const Command c = DecodeCommand(data);
    if (c[0] == kExecuteList) executed_ = Now();
    uint16_t status = kStatusReady;
    if (executed_ >= 0) {
      const bool first_wait = packets_ == 1 && Now() - executed_ < busy_s_;
      const bool running = Now() - std::max(executed_, last_packet_) < busy_s_;
      status = static_cast<uint16_t>((running ? kStatusBusy : 0) | (first_wait ? 0 : kStatusReady));
    }
    if (c[0] == kGetSerialNo || c[0] == kWriteCorLine) status = 0;
    replies_.push_back(status);
    return Status::Ok();
  }
  Status Read(uint8_t* data, size_t size) override {
    std::fill(data, data + size, 0);
    data[6] = static_cast<uint8_t>(replies_.front() & 0xFF);
    data[7] = static_cast<uint8_t>(replies_.front() >> 8);
    replies_.erase(replies_.begin());
    return Status::Ok();
  }
  std::string Describe() const override { return "scripted board"; }

 private:
  double Now() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }
  double busy_s_;
  const std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
  int packets_ = 0;
  double executed_ = -1.0, last_packet_ = -1.0;
  std::vector<uint16_t> replies_;
};

// The next packet waits for as long as the board is busy with the list before it (the old
// fixed limit took a legitimately long list for a dead board), reporting progress, and a
// cancel during that wait stops the board within a poll.
TEST(Lmc, APacketWaitsAsLongAsTheBoardIsBusy) {
  BoardOptions o = SimHeadBoard();
  o.packets_before_start = 1;
  GalvoList l;
  for (int k = 0; k < 200; ++k) {  // ~420 commands: two packets
    l.entries.push_back({GalvoListEntry::Kind::kJump, {-2.0, -2.0 + 0.02 * k, 0.0}});
    l.entries.push_back({GalvoListEntry::Kind::kJump, {2.0, -2.0 + 0.02 * k, 0.0}});
  }
  {
    auto lmc = MakeScanner(std::make_unique<BusyBoard>(1.2), o);
    std::vector<double> progress;
    ListControl control;
    control.progress = [&](double f) { progress.push_back(f); };
    const auto t0 = std::chrono::steady_clock::now();
    const Status ran = lmc->ExecuteList(l, control);
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(ran.ok()) << ran.ToString();
    EXPECT_GT(took, 2.0);  // 1.2 s for the second packet, 1.2 s for the list to end
    EXPECT_GT(progress.size(), 10u);
    EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));
  }
  {
    auto lmc = MakeScanner(std::make_unique<BusyBoard>(5.0), o);
    std::atomic<bool> abort{false};
    ListControl control;
    control.abort = &abort;
    std::thread stopper([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      abort = true;
    });
    const auto t0 = std::chrono::steady_clock::now();
    const Status ran = lmc->ExecuteList(l, control);
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    stopper.join();
    EXPECT_EQ(ran.code(), StatusCode::kCancelled) << ran.ToString();
    // Seen at the next poll (1 ms); the stop's flush then waits its half second for the
    // scripted board, still "busy".
    EXPECT_LT(took, 0.3 + 0.5 + 0.2);
  }
  {
    o.list_timeout_s = 0.5;  // a bound, when the job sets one
    auto lmc = MakeScanner(std::make_unique<BusyBoard>(5.0), o);
    const Status ran = lmc->ExecuteList(l);
    EXPECT_EQ(ran.code(), StatusCode::kDeviceError);
    EXPECT_NE(ran.message().find("list_timeout_s"), std::string::npos) << ran.ToString();
  }
}

// The lists of a decoded capture: the lines that are not comments, split at each "# list" head.
std::vector<std::string> DecodedLists(const std::string& decoded) {
  std::vector<std::string> lists;
  std::istringstream in(decoded);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("# list ", 0) == 0) {
      lists.emplace_back();
    } else if (!line.empty() && line[0] != '#' && !lists.empty()) {
      lists.back() += line + "\n";
    }
  }
  return lists;
}

int EndsOfList(const std::string& list) {
  int n = 0;
  for (size_t at = list.find("listEndOfList"); at != std::string::npos;
       at = list.find("listEndOfList", at + 1)) {
    ++n;
  }
  return n;
}

// insitu's own traffic, captured as pcapng and as usbmon text, decodes to the lists it sent:
// each with one end-of-list, the marking list exactly as the scanner says the board received
// it (what a mark job writes to galvo_list.txt), whatever its length around a packet's 256
// commands.
TEST(Lmc, ACaptureOfInsitusTrafficDecodesAsTheListsItSent) {
  const auto dir = std::filesystem::temp_directory_path() / "insitu_lmc_capture";
  std::filesystem::create_directories(dir);
  for (const char* name : {"traffic.pcapng", "traffic.txt"}) {
    // A marking list (the hatch: 76 commands) and lists of jumps of 255, 256, 257 and 512
    // commands (the list's 11 parameters and its jumps), then the list's end-of-list.
    for (int n : {0, 255, 256, 257, 512}) {
      SCOPED_TRACE(std::string(name) + (n ? ", " + std::to_string(n) + " commands" : ", hatch"));
      const std::string path = (dir / name).string();
      sim::WorldOptions w;
      w.part.kind = "none";
      std::string received;
      {
        auto board = Capturing(
            std::make_unique<SimBoard>(std::make_shared<sim::SimWorld>(w), SimHeadBoard()), path);
        ASSERT_TRUE(board.ok()) << board.status().ToString();
        auto lmc = OpenScanner(std::move(*board), SimHeadBoard());
        ASSERT_TRUE(lmc.ok()) << lmc.status().ToString();
        GalvoList l = Hatch(0.0);
        if (n > 0) {
          l = GalvoList{};
          for (int k = 0; k < n - 11; ++k) {
            l.entries.push_back({GalvoListEntry::Kind::kJump, {k % 2 ? 1.0 : -1.0, 0.0, 0.0}});
          }
        }
        ASSERT_TRUE((*lmc)->Arm().ok());
        ASSERT_TRUE((*lmc)->ExecuteList(l).ok());
        received = (*lmc)->ReceivedList();
        if (n > 0) {
          EXPECT_EQ(std::count(received.begin(), received.end(), '\n'), n + 1);  // and its end
        }
      }  // closed: the capture holds the stop at the end too
      const auto decoded = DecodeCaptureFile(path);
      ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
      const auto lists = DecodedLists(*decoded);
      ASSERT_GE(lists.size(), 2u);  // the marking list, the stop's flush
      for (const std::string& list : lists) EXPECT_EQ(EndsOfList(list), 1) << list;
      EXPECT_EQ(lists[lists.size() - 2], received);
      EXPECT_NE(decoded->find("# Reset "), std::string::npos);
      EXPECT_NE(decoded->find("# WriteCorTable"), std::string::npos);
    }
  }
}

// Captures made elsewhere: Windows USBPcap in classic pcap (EzCad's side), usbmon text as the
// kernel writes it (32 bytes of each transfer: a list packet is cut, and the decode says so),
// and a file that is none of them.
TEST(Lmc, CapturesFromOtherToolsDecodeOrSayWhyNot) {
  const auto le16 = [](std::string* s, uint16_t v) {
    s->push_back(static_cast<char>(v & 0xFF));
    s->push_back(static_cast<char>(v >> 8));
  };
  const auto le32 = [&](std::string* s, uint32_t v) {
    le16(s, static_cast<uint16_t>(v));
    le16(s, static_cast<uint16_t>(v >> 16));
  };
  std::vector<Command> list = {{kReadyMark, 0, 0, 0, 0, 0}, {kJumpTo, 0x8000, 0x8000, 0, 0, 0}};
  const auto packet = Packets(list).front();
  const auto reset = SingleCommand(kResetList), execute = SingleCommand(kExecuteList);
  // USBPcap: 27-byte header (length, IRP id, status, function, info, bus, device, endpoint,
  // transfer, data length), then the data; info bit 0 set on the completion, which carries none.
  const auto usbpcap = [&](const std::vector<uint8_t>& data, bool completion) {
    std::string p;
    le16(&p, 27);
    for (int i = 0; i < 8; ++i) p.push_back(0);
    le32(&p, 0);
    le16(&p, 0x0009);  // URB_FUNCTION_BULK_OR_INTERRUPT_TRANSFER
    p.push_back(completion ? 1 : 0);
    le16(&p, 1);
    le16(&p, 3);
    p.push_back(0x02);
    p.push_back(3);
    le32(&p, static_cast<uint32_t>(data.size()));
    if (!completion) p.append(data.begin(), data.end());
    return p;
  };
  std::string pcap;
  le32(&pcap, 0xa1b2c3d4);
  le16(&pcap, 2);
  le16(&pcap, 4);
  le32(&pcap, 0);
  le32(&pcap, 0);
  le32(&pcap, 65535);
  le32(&pcap, 249);
  for (const auto& [data, completion] : std::vector<std::pair<std::vector<uint8_t>, bool>>{
           {reset, false}, {reset, true}, {packet, false}, {packet, true}, {execute, false}}) {
    const std::string rec = usbpcap(data, completion);
    le32(&pcap, 0);
    le32(&pcap, 0);
    le32(&pcap, static_cast<uint32_t>(rec.size()));
    le32(&pcap, static_cast<uint32_t>(rec.size()));
    pcap += rec;
  }
  const auto transfers = ReadCapture(pcap, "ezcad.pcap");
  ASSERT_TRUE(transfers.ok()) << transfers.status().ToString();
  ASSERT_EQ(transfers->size(), 3u);  // the completions carry no OUT data
  const std::string decoded = DecodeTraffic(*transfers);
  const auto lists = DecodedLists(decoded);
  ASSERT_EQ(lists.size(), 1u);
  EXPECT_EQ(lists[0], FormatCommands({list[0], list[1], {kEndOfList, 0, 0, 0, 0, 0}}));
  EXPECT_NE(decoded.find("# ResetList"), std::string::npos);
  EXPECT_NE(decoded.find("# ExecuteList"), std::string::npos);

  // The kernel's usbmon text: a command whole, a list packet cut at 32 bytes.
  const std::string text =
      "ffff8b29 0990 S Bo:1:003:2 -115 31 = 55534243 01000000 00020000 80000a28 00000000 "
      "00000000 00000000 000000\n"  // a disk's command block on the same bus: not the board
      "ffff8b2a 1000 S Bo:1:005:2 -115 12 = 12000000 00000000 00000000\n"
      "ffff8b2a 1010 C Bo:1:005:2 0 12 >\n"
      "ffff8b2b 1020 S Bo:1:005:2 -115 3072 = 51800000 00000000 00000000 01800080 00800000 "
      "00000000 02800000 00000000\n";
  const auto cut = ReadCapture(text, "usbmon.txt");
  ASSERT_TRUE(cut.ok()) << cut.status().ToString();
  ASSERT_EQ(cut->size(), 3u);
  EXPECT_EQ((*cut)[2].length, 3072u);
  EXPECT_EQ((*cut)[2].data.size(), 32u);
  EXPECT_EQ((*cut)[2].device, 5);
  const std::string cut_decoded = DecodeTraffic(*cut);
  EXPECT_NE(cut_decoded.find("skipped: bus 1 device 3 (1 transfers)"), std::string::npos)
      << cut_decoded;
  EXPECT_EQ(cut_decoded.find("55534243"), std::string::npos);
  EXPECT_NE(cut_decoded.find("cut by the capture"), std::string::npos) << cut_decoded;
  EXPECT_NE(cut_decoded.find("pcapng"), std::string::npos);

  const auto junk = ReadCapture("hello\nworld\n", "notes.txt");
  EXPECT_EQ(junk.status().code(), StatusCode::kParseError);
  EXPECT_NE(junk.status().message().find("notes.txt"), std::string::npos);
  std::string other_link = pcap.substr(0, 24);
  other_link[20] = 1;  // Ethernet
  other_link[21] = 0;
  EXPECT_EQ(ReadCapture(other_link, "eth.pcap").status().code(), StatusCode::kParseError);
  EXPECT_EQ(DecodeCaptureFile("/nonexistent/capture.pcapng").status().code(),
            StatusCode::kNotFound);
}

TEST(Lmc, NoBoardIsAClearError) {
  UsbSelector s;
  s.vid = 0x9588;
  s.pid = 0x0001;  // no such board
  const auto t = OpenUsb(s);
  ASSERT_FALSE(t.ok());
  // No USB bus in a container is a device error from libusb; a bus without the board, not found.
  EXPECT_TRUE(t.status().code() == StatusCode::kNotFound ||
              t.status().code() == StatusCode::kDeviceError);
  const std::string& m = t.status().message();
  EXPECT_TRUE(m.find("9588:0001") != std::string::npos || m.find("libusb") != std::string::npos)
      << m;
}

}  // namespace
}  // namespace insitu::hw::lmc
