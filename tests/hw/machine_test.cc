#include "insitu/hw/cell.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "insitu/hw/sim_backend.h"
#include "support/grbl_emulator.h"

namespace insitu::hw {
namespace {

TEST(Machine, UnknownBackendIsRefusedNamingTheKnownOnes) {
  MachineConfig config;
  config.backend = "aravis";
  auto m = CreateMachine(config);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kNotFound);
  EXPECT_NE(m.status().message().find("sim"), std::string::npos);
}

TEST(Machine, SimBackendValidatesTheWorld) {
  MachineConfig config;
  config.world.camera.f_number = 0.1;
  auto m = CreateMachine(config);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("f_number"), std::string::npos);
}

// The marking laser fires only while armed.
TEST(Machine, MarkingListNeedsTheHeadArmed) {
  MachineConfig config;
  auto m = CreateMachine(config);
  ASSERT_TRUE(m.ok());
  GalvoList list;
  list.entries.push_back({GalvoListEntry::Kind::kJump, {0, 0, 0}});
  list.entries.push_back({GalvoListEntry::Kind::kMark, {10, 0, 0}});
  EXPECT_EQ(m->scanner->ExecuteList(list).code(), StatusCode::kFailedPrecondition);
  ASSERT_TRUE(m->scanner->Arm().ok());
  EXPECT_TRUE(m->scanner->ExecuteList(list).ok());
  ASSERT_TRUE(m->scanner->Disarm().ok());
  EXPECT_FALSE(m->scanner->armed());
}

TEST(Machine, DevicesShareOneClock) {
  auto world = std::make_shared<sim::SimWorld>(sim::WorldOptions{});
  Machine m = MakeSimMachine(world);
  const double t0 = m.clock->Now();
  ASSERT_TRUE(m.stage->MoveTo(5.0).ok());  // 5 mm at 10 mm/s
  EXPECT_NEAR(m.clock->Now() - t0, 0.5, 1e-9);
  EXPECT_NEAR(*m.stage->Position(), 5.0, 1e-12);
  EXPECT_EQ(m.stage->MoveTo(50.0).code(), StatusCode::kOutOfRange);
}

// A simulated cell: every role the world has is the simulator's, on its clock.
TEST(Cell, ASimulatedCellHasEveryRoleTheWorldHas) {
  MachineConfig config;
  config.world.gantry.present = true;
  config.world.profiler.present = true;
  auto m = CreateMachine(config);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_FALSE(m->real);
  for (Role r : kRoles) {
    if (r == Role::kCoaxial) continue;  // the default world's head has none
    EXPECT_TRUE(m->Has(r)) << RoleKey(r);
  }
  EXPECT_EQ(m->Has(Role::kCoaxial), config.world.scan_head.coaxial.present);
  EXPECT_TRUE(m->warnings.empty());
  EXPECT_TRUE(m->Require({Role::kScanner, Role::kStage, Role::kOperator}, "a job").ok());
}

// A role named none has no device; a job that needs it is refused naming the role's key.
TEST(Cell, AJobIsRefusedARoleTheCellDoesNotHave) {
  MachineConfig config;
  config.stage = "none";
  auto m = CreateMachine(config);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_FALSE(m->Has(Role::kStage));
  const Status refused = m->Require({Role::kScanner, Role::kStage}, "the calibrate job");
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.message().find("the calibrate job needs a Z stage"), std::string::npos)
      << refused.message();
  EXPECT_NE(refused.message().find("machine.stage"), std::string::npos);
}

TEST(Cell, UnknownDevicesAndAbsentSimulatedOnesAreRefusedByRole) {
  MachineConfig config;
  config.stage = "zaber";
  auto unknown = CreateMachine(config);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("machine.stage: no device 'zaber'"),
            std::string::npos)
      << unknown.status().message();
  MachineConfig coaxial;
  coaxial.coaxial = "sim";
  coaxial.world.scan_head.coaxial.present = false;
  auto absent = CreateMachine(coaxial);
  ASSERT_FALSE(absent.ok());
  EXPECT_NE(absent.status().message().find("machine.coaxial"), std::string::npos);
}

// A person as the operator: asked first, then (on a simulated cell) the simulator's hands do
// it. Without a way to ask, such a cell does not come up; their refusal cancels.
TEST(Cell, APersonIsAskedBeforeTheSimulatedHandsAct) {
  MachineConfig config;
  config.person = "person";
  config.world.board.present = true;
  auto unasked = CreateMachine(config);
  ASSERT_FALSE(unasked.ok());
  EXPECT_EQ(unasked.status().code(), StatusCode::kFailedPrecondition);
  std::vector<std::string> asked;
  bool refuse = false;
  config.ask_person = [&](const std::string& request) {
    asked.push_back(request);
    return refuse ? Status(StatusCode::kCancelled, "no") : Status::Ok();
  };
  auto m = CreateMachine(config);
  ASSERT_TRUE(m.ok()) << m.status().message();
  ASSERT_TRUE(m->person->PlaceBoard(2, 12).ok());
  ASSERT_EQ(asked.size(), 1u);
  EXPECT_NE(asked[0].find("view 3 of 12"), std::string::npos) << asked[0];
  refuse = true;
  EXPECT_EQ(m->person->ClearTable().code(), StatusCode::kCancelled);
}

// A real device makes the cell real: roles it does not name have no device (nothing silently
// simulated), and one that cannot be opened is an error naming its role.
TEST(Cell, ARealDeviceThatCannotOpenIsAnErrorNamingItsRole) {
  MachineConfig config;
  config.scanner = "lmc";
  config.lmc.transport = "usb";
  config.lmc.usb.vid = 0x9588;
  config.lmc.usb.pid = 0x0fff;  // no such board on a test machine
  EXPECT_TRUE(IsRealCell(config));
  EXPECT_FALSE(NeedsSimulator(config));
  EXPECT_EQ(DeviceFor(config, Role::kStage), "none");
  EXPECT_EQ(DeviceFor(config, Role::kOperator), "none");
  auto m = CreateMachine(config);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().message().rfind("machine.scanner", 0), 0u) << m.status().message();
  config.stage = "sim";
  EXPECT_TRUE(NeedsSimulator(config));
}

// A real stage (a GRBL controller, here its emulator on a pseudo-terminal) makes the cell
// real: the roles it does not name have no device, a job needing one is refused by name, and
// a simulated device must be named, which the cell reports as a dry run.
TEST(Cell, ARealStageMakesARealCellWithNothingSimulatedUnlessNamed) {
  testing::GrblEmulatorOptions fast;
  fast.time_scale = 0.05;
  testing::GrblEmulator emulator(fast);
  MachineConfig config;
  config.stage = "grbl";
  config.grbl.port = emulator.port();
  config.grbl.min_z_mm = -19.0;
  config.grbl.max_z_mm = 29.0;
  config.grbl.machine_zero_mm = -30.0;
  config.grbl.banner_wait_s = 0.05;
  config.grbl.status_poll_s = 0.01;
  EXPECT_FALSE(NeedsSimulator(config));
  {
    auto m = CreateMachine(config);
    ASSERT_TRUE(m.ok()) << m.status().message();
    EXPECT_TRUE(m->real);
    EXPECT_TRUE(m->Has(Role::kStage));
    for (Role r : {Role::kScanner, Role::kCamera, Role::kCoaxial, Role::kAxis, Role::kProfiler,
                   Role::kOperator}) {
      EXPECT_FALSE(m->Has(r)) << RoleKey(r);
    }
    EXPECT_TRUE(m->warnings.empty());
    const Status refused = m->Require({Role::kStage, Role::kScanner}, "the scan job");
    EXPECT_NE(refused.message().find("machine.scanner names no device on this real cell"),
              std::string::npos)
        << refused.message();
    ASSERT_TRUE(m->stage->MoveTo(2.0).ok());
    EXPECT_NEAR(emulator.machine_z_mm(), -28.0, 1e-9);
  }
  config.scanner = "sim";
  EXPECT_TRUE(NeedsSimulator(config));
  auto dry = CreateMachine(config);
  ASSERT_TRUE(dry.ok()) << dry.status().message();
  EXPECT_TRUE(dry->Has(Role::kScanner));
  EXPECT_FALSE(dry->Has(Role::kCamera));
  ASSERT_EQ(dry->warnings.size(), 1u);
  EXPECT_EQ(dry->warnings[0].rfind("dry run: the scan head is simulated (machine.scanner: sim)", 0),
            0u)
      << dry->warnings[0];
}

}  // namespace
// Injected device faults come back as device errors naming what failed; the head is
// disarmed by its own fault; nothing else breaks.
TEST(Machine, InjectedFaultsAreDeviceErrors) {
  sim::WorldOptions w;
  w.faults.camera_timeout_at_frame = 0;
  w.faults.scanner_error_at_command = 0;
  w.faults.stage_stuck = true;
  Machine m = MakeSimMachine(std::make_shared<sim::SimWorld>(w));
  const auto frame = m.camera->Grab();
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(frame.status().message().find("camera timeout"), std::string::npos);
  EXPECT_TRUE(m.camera->Grab().ok());  // the next frame arrives
  ASSERT_TRUE(m.scanner->Arm().ok());
  const Status line = m.scanner->StartPointerLine({0, -5, 0}, {0, 5, 0}, 1000.0);
  EXPECT_EQ(line.code(), StatusCode::kDeviceError);
  EXPECT_FALSE(m.scanner->armed());  // a faulted head is not left armed
  const Status stage = m.stage->MoveTo(5.0);
  EXPECT_EQ(stage.code(), StatusCode::kDeviceError);
  EXPECT_NE(stage.message().find("did not arrive"), std::string::npos);
}

// A frame that lost packets is an error; one whose payload does not match its header is
// caught by Camera::Grab before any image code could read past its end.
TEST(Machine, DroppedAndCorruptFramesAreDeviceErrors) {
  sim::WorldOptions w;
  w.faults.camera_drop_frame_at = 0;
  w.faults.camera_corrupt_frame_at = 1;
  Machine m = MakeSimMachine(std::make_shared<sim::SimWorld>(w));
  const auto dropped = m.camera->Grab();
  ASSERT_FALSE(dropped.ok());
  EXPECT_EQ(dropped.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(dropped.status().message().find("packets lost"), std::string::npos);
  const auto corrupt = m.camera->Grab();
  ASSERT_FALSE(corrupt.ok());
  EXPECT_EQ(corrupt.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(corrupt.status().message().find("corrupt"), std::string::npos)
      << corrupt.status().message();
  EXPECT_TRUE(m.camera->Grab().ok());  // the next frame is whole
}

TEST(Machine, CheckFrameNamesWhatIsWrong) {
  const CameraInfo info{"cam", "1", 64, 48, 12};
  Frame f;
  f.width = 32;
  f.height = 24;
  f.bit_depth = 12;
  f.binning = 2;
  f.bytes.assign(32 * 24 * 2, 0);
  EXPECT_TRUE(CheckFrame(f, info).ok());
  Frame short_payload = f;
  short_payload.bytes.resize(100);
  EXPECT_NE(CheckFrame(short_payload, info).message().find("payload is 100 bytes"),
            std::string::npos);
  Frame eight_bit = f;
  eight_bit.bit_depth = 8;
  eight_bit.bytes.resize(32 * 24);
  EXPECT_NE(CheckFrame(eight_bit, info).message().find("set to 12 bits"), std::string::npos);
  Frame unbinned = f;  // 32 x 24 px claimed at binning 4 of a 64 x 48 sensor: too large
  unbinned.binning = 4;
  EXPECT_NE(CheckFrame(unbinned, info).message().find("does not fit"), std::string::npos);
}

}  // namespace insitu::hw
