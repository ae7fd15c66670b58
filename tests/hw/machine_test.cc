#include "insitu/hw/machine.h"

#include <gtest/gtest.h>

#include "insitu/hw/sim_backend.h"

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
