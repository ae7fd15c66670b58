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
#include <random>
#include <thread>

#include "hw/lmc/sim_board.h"
#include "insitu/hw/cell.h"
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
    auto lmc = MakeScanner(std::move(board), SimHeadBoard());
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
  auto lmc = MakeScanner(std::move(board), o);
  GalvoList l = Hatch(0.0);
  l.entries.clear();
  for (int k = 0; k < 150; ++k) {  // 150 lines: ~610 commands, 3 packets
    const double y = -15.0 + 0.2 * k;
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
uint16_t StatusWord(Transport& board, uint16_t op) {
  const auto bytes = SingleCommand(op);
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
  auto lmc = MakeScanner(std::move(board), SimHeadBoard());
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
  auto lmc = MakeScanner(std::move(board), SimHeadBoard());
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
