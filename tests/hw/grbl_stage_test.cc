// The GRBL stage against a GRBL 1.1 emulator on a pseudo-terminal (tests/support): homing,
// moves in the cell's frame, the travel checked before anything is sent, the controller's
// errors and alarms named with their meaning, a held or unplugged or silent controller failing
// within its deadline; the options' checks; the status line parser on malformed input.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "hw/grbl/protocol.h"
#include "hw/grbl/stage.h"
#include "support/grbl_emulator.h"

namespace insitu::hw::grbl {
namespace {

using testing::GrblEmulator;
using testing::GrblEmulatorOptions;
using Clock = std::chrono::steady_clock;

// Reports carry 3 decimals (GRBL's mm format): a position read back is within half of 0.001 mm.
constexpr double kReportQuantumMm = 0.0005;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

bool Has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

bool Received(const GrblEmulator& emulator, const std::string& prefix) {
  const auto lines = emulator.lines();
  return std::any_of(lines.begin(), lines.end(),
                     [&](const std::string& l) { return l.rfind(prefix, 0) == 0; });
}

// The cell's z = 0 at machine Z -30, up +: the travel [-19, 29] is machine [-49, -1], inside
// the emulator's [-50, 0]. Homing leaves machine Z at -1 (its pull-off), the cell's z = 29.
StageOptions Options(const GrblEmulator& emulator) {
  StageOptions o;
  o.port = emulator.port();
  o.min_z_mm = -19.0;
  o.max_z_mm = 29.0;
  o.machine_zero_mm = -30.0;
  o.feed_mm_per_min = 600.0;
  o.timeout_s = 0.3;
  o.homing_timeout_s = 1.0;
  o.banner_wait_s = 0.05;
  o.status_poll_s = 0.01;
  return o;
}

GrblEmulatorOptions Fast() {
  GrblEmulatorOptions e;
  e.time_scale = 0.05;  // 600 mm/min: 30 mm in 0.15 s
  return e;
}

TEST(GrblStage, HomesMovesAndReportsPositionInTheCellFrame) {
  GrblEmulator emulator(Fast());  // homing enabled: it starts in Alarm
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  EXPECT_TRUE(Received(emulator, "$H"));
  EXPECT_EQ(emulator.state(), "Idle");
  EXPECT_EQ((*stage)->min_z_mm(), -19.0);
  EXPECT_EQ((*stage)->max_z_mm(), 29.0);

  auto z = (*stage)->Position();
  ASSERT_TRUE(z.ok()) << z.status().ToString();
  EXPECT_NEAR(*z, 29.0, kReportQuantumMm);

  ASSERT_TRUE((*stage)->MoveTo(0.0).ok());
  EXPECT_NEAR(emulator.machine_z_mm(), -30.0, 1e-9);
  z = (*stage)->Position();
  ASSERT_TRUE(z.ok());
  EXPECT_NEAR(*z, 0.0, kReportQuantumMm);

  const Status moved = (*stage)->MoveTo(-12.5);
  ASSERT_TRUE(moved.ok()) << moved.ToString();
  EXPECT_NEAR(emulator.machine_z_mm(), -42.5, 1e-9);
  EXPECT_TRUE(Received(emulator, "G21 G90 G53 G1 Z-42.5000 F600.0"));
  z = (*stage)->Position();
  ASSERT_TRUE(z.ok());
  EXPECT_NEAR(*z, -12.5, kReportQuantumMm);
}

// Controller + is down in the cell, and the controller reports WPos with the work offset (WCO)
// only now and then: positions still come out in the cell's frame, moves still in machine Z.
TEST(GrblStage, DownwardAxisAndWorkPositionReports) {
  GrblEmulatorOptions e = Fast();
  e.report_wpos = true;
  e.wco_z_mm = 7.5;
  GrblEmulator emulator(e);
  StageOptions o = Options(emulator);
  o.direction = -1;
  o.machine_zero_mm = -45.0;  // machine = -45 - z: the travel [-40, 4] is machine [-49, -5]
  o.min_z_mm = -40.0;
  o.max_z_mm = 4.0;
  auto stage = OpenStage(o);
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();

  auto z = (*stage)->Position();
  ASSERT_TRUE(z.ok()) << z.status().ToString();
  EXPECT_NEAR(*z, -44.0, kReportQuantumMm);  // machine -1 after homing

  ASSERT_TRUE((*stage)->MoveTo(4.0).ok());
  EXPECT_NEAR(emulator.machine_z_mm(), -49.0, 1e-9);
  const Status moved = (*stage)->MoveTo(-10.0);
  ASSERT_TRUE(moved.ok()) << moved.ToString();
  EXPECT_NEAR(emulator.machine_z_mm(), -35.0, 1e-9);
  z = (*stage)->Position();
  ASSERT_TRUE(z.ok());
  EXPECT_NEAR(*z, -10.0, kReportQuantumMm);
}

TEST(GrblStage, TargetOutsideTheTravelIsRefusedBeforeAnythingIsSent) {
  GrblEmulator emulator(Fast());
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  const size_t sent = emulator.lines().size();
  for (const double z : {29.001, -19.5, std::numeric_limits<double>::quiet_NaN()}) {
    const Status s = (*stage)->MoveTo(z);
    EXPECT_EQ(s.code(), StatusCode::kOutOfRange) << s.ToString();
    EXPECT_TRUE(Has(s.message(), "outside the stage's travel [-19.000, 29.000] mm")) << s.message();
  }
  EXPECT_EQ(emulator.lines().size(), sent);
  EXPECT_NEAR(emulator.machine_z_mm(), -1.0, 1e-9);
}

// The stage's travel is configured beyond the controller's (machine Z up to +10 > 0): GRBL
// refuses the motion with its soft limit alarm, which the stage names, and after it the stage
// reports the alarm at once (the controller was reset out of its wait) instead of timing out.
TEST(GrblStage, ControllerSoftLimitSurfacesWithItsMeaning) {
  GrblEmulator emulator(Fast());
  StageOptions o = Options(emulator);
  o.max_z_mm = 40.0;
  auto stage = OpenStage(o);
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();

  const Status s = (*stage)->MoveTo(35.0);
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(s.message(), "ALARM:2 (soft limit")) << s.message();
  EXPECT_TRUE(Has(s.message(), "move to z = 35.000 mm (machine Z5.0000)")) << s.message();
  EXPECT_NEAR(emulator.machine_z_mm(), -1.0, 1e-9);

  const auto start = Clock::now();
  const auto z = (*stage)->Position();
  EXPECT_FALSE(z.ok());
  EXPECT_TRUE(Has(z.status().message(), "in ALARM since ALARM:2")) << z.status().message();
  const Status again = (*stage)->MoveTo(0.0);
  EXPECT_TRUE(Has(again.message(), "in ALARM since ALARM:2")) << again.message();
  EXPECT_LT(Seconds(start), o.timeout_s);  // answered, not timed out
}

TEST(GrblStage, RefusedLineNamesTheErrorAndItsMeaning) {
  GrblEmulator emulator(Fast());
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  emulator.RefuseNextLine(20);
  const Status s = (*stage)->MoveTo(0.0);
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(s.message(), "error:20 (unsupported or invalid G-code command)")) << s.message();
  EXPECT_TRUE(Has(s.message(), "GRBL on " + emulator.port())) << s.message();
  // A refused line leaves the controller as it was: the next move goes through.
  const Status next = (*stage)->MoveTo(0.0);
  EXPECT_TRUE(next.ok()) << next.ToString();
}

TEST(GrblStage, HardLimitMidMoveFaultsWithTheAlarm) {
  GrblEmulator emulator(Fast());
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  emulator.SetLimitSwitchAt(-20.0);  // between machine -1 and the target -40
  const Status s = (*stage)->MoveTo(-10.0);
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(s.message(), "ALARM:1 (hard limit triggered")) << s.message();
  EXPECT_NEAR(emulator.machine_z_mm(), -20.0, 1e-9);

  const auto start = Clock::now();
  const Status again = (*stage)->MoveTo(0.0);
  EXPECT_EQ(again.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(again.message(), "in ALARM since ALARM:1")) << again.message();
  EXPECT_LT(Seconds(start), 0.2);
}

TEST(GrblStage, FeedHoldDuringAMoveFaultsNamingTheState) {
  GrblEmulatorOptions e = Fast();
  e.time_scale = 1.0;  // 48 mm at 600 mm/min: 4.8 s, held after 0.05 s
  GrblEmulator emulator(e);
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  std::thread hold([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    emulator.FeedHold();
  });
  const auto start = Clock::now();
  const Status s = (*stage)->MoveTo(-19.0);
  hold.join();
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(s.message(), "Hold:0 (feed hold complete")) << s.message();
  EXPECT_LT(Seconds(start), 0.5);
}

TEST(GrblStage, StartingInAlarmWithoutHomeOnOpenIsRefused) {
  GrblEmulator emulator(Fast());
  StageOptions o = Options(emulator);
  o.home_on_open = false;
  auto stage = OpenStage(o);
  ASSERT_FALSE(stage.ok());
  EXPECT_EQ(stage.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_TRUE(Has(stage.status().message(), "is in ALARM (homing is enabled, $22=1"))
      << stage.status().message();
  EXPECT_TRUE(Has(stage.status().message(), "home_on_open")) << stage.status().message();
  // Neither homed nor unlocked behind the operator's back.
  EXPECT_FALSE(Received(emulator, "$H"));
  EXPECT_FALSE(Received(emulator, "$X"));
  EXPECT_EQ(emulator.state(), "Alarm");
}

TEST(GrblStage, ControllerWithoutHomingOpensWithoutHoming) {
  GrblEmulatorOptions e = Fast();
  e.homing_enabled = false;
  e.soft_limits = false;
  GrblEmulator emulator(e);
  StageOptions o = Options(emulator);
  o.home_on_open = false;
  auto stage = OpenStage(o);
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  EXPECT_FALSE(Received(emulator, "$H"));
  const auto z = (*stage)->Position();
  ASSERT_TRUE(z.ok());
  EXPECT_NEAR(*z, 30.0, kReportQuantumMm);  // machine 0 at power-up
  EXPECT_TRUE((*stage)->MoveTo(1.0).ok());
  EXPECT_NEAR(emulator.machine_z_mm(), -29.0, 1e-9);
}

TEST(GrblStage, HomeOnOpenWithHomingDisabledIsRefused) {
  GrblEmulatorOptions e = Fast();
  e.homing_enabled = false;
  GrblEmulator emulator(e);
  auto stage = OpenStage(Options(emulator));
  ASSERT_FALSE(stage.ok());
  EXPECT_EQ(stage.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_TRUE(Has(stage.status().message(), "homing is disabled on the controller ($22=0)"))
      << stage.status().message();
}

TEST(GrblStage, HomingFailureNamesTheAlarm) {
  GrblEmulator emulator(Fast());
  emulator.FailHoming(9);
  auto stage = OpenStage(Options(emulator));
  ASSERT_FALSE(stage.ok());
  EXPECT_EQ(stage.status().code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(stage.status().message(),
                  "homing ($H) failed: ALARM:9 (homing fail: the limit switch was not found"))
      << stage.status().message();
}

TEST(GrblStage, UnpluggedPortFaultsAndEveryLaterCallFailsAtOnce) {
  GrblEmulator emulator(Fast());
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  emulator.Unplug();
  const auto z = (*stage)->Position();
  ASSERT_FALSE(z.ok());
  EXPECT_EQ(z.status().code(), StatusCode::kDeviceError);
  const std::string lost = "lost the serial port " + emulator.port() + ": ";
  EXPECT_TRUE(Has(z.status().message(), lost)) << z.status().message();

  const auto start = Clock::now();
  const Status move = (*stage)->MoveTo(0.0);
  EXPECT_EQ(move.message(), z.status().message());
  EXPECT_EQ((*stage)->Position().status().message(), z.status().message());
  EXPECT_LT(Seconds(start), 0.05);
}

TEST(GrblStage, UnplugDuringAMoveFaults) {
  GrblEmulatorOptions e = Fast();
  e.time_scale = 1.0;  // 48 mm at 600 mm/min: 4.8 s, unplugged after 0.05 s
  GrblEmulator emulator(e);
  auto stage = OpenStage(Options(emulator));
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  std::thread unplug([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    emulator.Unplug();
  });
  const auto start = Clock::now();
  const Status s = (*stage)->MoveTo(-19.0);
  unplug.join();
  EXPECT_EQ(s.code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(s.message(), "lost the serial port " + emulator.port())) << s.message();
  EXPECT_LT(Seconds(start), 0.5);
}

TEST(GrblStage, SilentControllerTimesOutWithAClearError) {
  GrblEmulator emulator(Fast());
  emulator.SetMute(true);
  const StageOptions o = Options(emulator);
  const auto start = Clock::now();
  auto stage = OpenStage(o);
  const double took = Seconds(start);
  ASSERT_FALSE(stage.ok());
  EXPECT_EQ(stage.status().code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(stage.status().message(), "no reply: no GRBL banner"))
      << stage.status().message();
  // Its deadlines: the banner wait, then the reply deadline after the soft reset.
  EXPECT_GE(took, o.banner_wait_s + o.timeout_s - 0.01);
  EXPECT_LT(took, o.banner_wait_s + o.timeout_s + 0.2);
}

TEST(GrblStage, ControllerThatStopsAnsweringTimesOut) {
  GrblEmulator emulator(Fast());
  const StageOptions o = Options(emulator);
  auto stage = OpenStage(o);
  ASSERT_TRUE(stage.ok()) << stage.status().ToString();
  emulator.SetMute(true);
  auto start = Clock::now();
  const auto z = (*stage)->Position();
  ASSERT_FALSE(z.ok());
  EXPECT_EQ(z.status().code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(z.status().message(), "no reply to the status query '?' within 0.3 s"))
      << z.status().message();
  EXPECT_LT(Seconds(start), o.timeout_s + 0.2);
  start = Clock::now();
  const Status move = (*stage)->MoveTo(0.0);
  EXPECT_TRUE(Has(move.message(), "no reply")) << move.message();
  EXPECT_LT(Seconds(start), o.timeout_s + 0.2);
}

TEST(GrblStage, PortHeldByAnotherStageOrMissingIsRefused) {
  GrblEmulator emulator(Fast());
  auto first = OpenStage(Options(emulator));
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  auto second = OpenStage(Options(emulator));
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), StatusCode::kDeviceError);
  EXPECT_TRUE(Has(second.status().message(), "held by another program"))
      << second.status().message();

  StageOptions o = Options(emulator);
  o.port = "/dev/no-such-grbl-port";
  auto missing = OpenStage(o);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Has(missing.status().message(), "/dev/no-such-grbl-port"));
}

TEST(GrblStageOptions, ValidateNamesTheField) {
  const auto valid = [] {
    StageOptions o;
    o.port = "/dev/ttyUSB0";
    o.min_z_mm = -10.0;
    o.max_z_mm = 10.0;
    return o;
  };
  EXPECT_TRUE(valid().Validate().ok());
  EXPECT_EQ(StageOptions().Validate().code(), StatusCode::kInvalidArgument);

  struct Case {
    const char* field;
    void (*spoil)(StageOptions&);
  };
  const Case cases[] = {
      {"port", [](StageOptions& o) { o.port.clear(); }},
      {"baud", [](StageOptions& o) { o.baud = 250000; }},
      {"axis", [](StageOptions& o) { o.axis = 'W'; }},
      {"axis", [](StageOptions& o) { o.axis = 'z'; }},
      {"min_z_mm", [](StageOptions& o) { o.min_z_mm = 10.0; }},
      {"min_z_mm", [](StageOptions& o) { o.max_z_mm = std::nan(""); }},
      {"machine_zero_mm", [](StageOptions& o) { o.machine_zero_mm = INFINITY; }},
      {"direction", [](StageOptions& o) { o.direction = 0; }},
      {"feed_mm_per_min", [](StageOptions& o) { o.feed_mm_per_min = 0.0; }},
      {"timeout_s", [](StageOptions& o) { o.timeout_s = -1.0; }},
      {"homing_timeout_s", [](StageOptions& o) { o.homing_timeout_s = 0.0; }},
      {"banner_wait_s", [](StageOptions& o) { o.banner_wait_s = -0.1; }},
      {"status_poll_s", [](StageOptions& o) { o.status_poll_s = 0.0; }},
      {"position_tolerance_mm", [](StageOptions& o) { o.position_tolerance_mm = 0.0; }},
  };
  for (const Case& c : cases) {
    StageOptions o = valid();
    c.spoil(o);
    const Status s = o.Validate();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.field;
    EXPECT_EQ(s.message().rfind(c.field, 0), 0u) << c.field << ": " << s.message();
    // OpenStage refuses it before touching any port.
    EXPECT_EQ(OpenStage(o).status().code(), StatusCode::kInvalidArgument) << c.field;
  }
}

TEST(GrblProtocol, ParsesStatusReports) {
  auto r = ParseStatusReport("<Idle|MPos:1.000,-2.500,-10.125|Bf:15,128|FS:0,0|WCO:0,0,7.5>");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->state, "Idle");
  EXPECT_EQ(r->substate, -1);
  ASSERT_EQ(r->mpos.size(), 3u);
  EXPECT_EQ(r->mpos[2], -10.125);
  ASSERT_EQ(r->wco.size(), 3u);
  EXPECT_EQ(r->wco[2], 7.5);
  EXPECT_TRUE(r->wpos.empty());

  r = ParseStatusReport("<Door:1|WPos:0.000,0.000,3.000,90.000>");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->state, "Door");
  EXPECT_EQ(r->substate, 1);
  EXPECT_EQ(r->wpos.size(), 4u);
  EXPECT_EQ(DescribeState(*r), "Door:1 (safety door open, machine stopped)");

  for (const char* bad : {"", "<>", "<Idle|MPos:1,2,3", "Idle|MPos:1,2,3>", "<Walk|MPos:1,2,3>",
                          "<Hold:x|MPos:1,2,3>", "<Idle|MPos:1,,3>", "<Idle|MPos:1,2,3a>",
                          "<Idle|MPos>", "<Idle|FS:0,0>", "<Idle|WPos:>", "<|MPos:1,2,3>",
                          // A corrupted number is no position: nan, inf, beyond a kilometre.
                          "<Idle|MPos:0,0,nan>", "<Idle|MPos:0,0,inf>", "<Idle|MPos:0,0,-1e300>",
                          "<Idle|MPos:0,0,0|WCO:0,0,nan>"}) {
    const auto parsed = ParseStatusReport(bad);
    EXPECT_FALSE(parsed.ok()) << bad;
    EXPECT_EQ(parsed.status().code(), StatusCode::kParseError) << bad;
  }
}

TEST(GrblProtocol, ClassifiesLinesAndNamesCodes) {
  EXPECT_EQ(Classify("ok").kind, LineKind::kOk);
  EXPECT_EQ(Classify("error:15").kind, LineKind::kError);
  EXPECT_EQ(Classify("error:15").code, 15);
  EXPECT_EQ(Classify("error:x").code, -1);
  EXPECT_EQ(Classify("ALARM:2").kind, LineKind::kAlarm);
  EXPECT_EQ(Classify("ALARM:2").code, 2);
  EXPECT_EQ(Classify("<Run|MPos:0,0,0>").kind, LineKind::kStatus);
  EXPECT_EQ(Classify("Grbl 1.1h ['$' for help]").kind, LineKind::kBanner);
  EXPECT_EQ(Classify("[MSG:'$H'|'$X' to unlock]").kind, LineKind::kMessage);
  EXPECT_EQ(Classify("$22=1").kind, LineKind::kSetting);
  EXPECT_EQ(Classify("$N0=G54").kind, LineKind::kOther);
  EXPECT_EQ(Classify("okay").kind, LineKind::kOther);

  EXPECT_TRUE(Has(DescribeError(15), "soft limit"));
  EXPECT_TRUE(Has(DescribeError(9), "locked out"));
  EXPECT_TRUE(Has(DescribeError(22), "feed rate"));
  EXPECT_TRUE(Has(DescribeError(99), "error:99 (an error code GRBL 1.1 does not define)"));
  EXPECT_TRUE(Has(DescribeAlarm(1), "hard limit"));
  EXPECT_TRUE(Has(DescribeAlarm(2), "soft limit"));
  EXPECT_TRUE(Has(DescribeAlarm(3), "reset while in motion"));
  EXPECT_TRUE(Has(DescribeAlarm(8), "pulling off"));
  EXPECT_TRUE(Has(DescribeAlarm(42), "ALARM:42 (an alarm code"));

  const auto setting = ParseSetting("$132=50.000");
  ASSERT_TRUE(setting.has_value());
  EXPECT_EQ(setting->first, 132);
  EXPECT_EQ(setting->second, 50.0);
  for (const char* bad : {"$132", "$=1", "$x=1", "$13=", "$13=1mm", "13=1"}) {
    EXPECT_FALSE(ParseSetting(bad).has_value()) << bad;
  }
  EXPECT_TRUE(IsVersion11("Grbl 1.1h ['$' for help]"));
  EXPECT_TRUE(IsVersion11("GrblHAL 1.1f ['$' or '$HELP' for help]"));
  EXPECT_FALSE(IsVersion11("Grbl 0.9j ['$' for help]"));
  EXPECT_FALSE(IsVersion11("Grbl"));
}

}  // namespace
}  // namespace insitu::hw::grbl
