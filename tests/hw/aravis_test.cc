// The Aravis camera backend against a real GigE Vision peer: Aravis's fake camera on a loopback
// address, its frames rendered by the simulator. Frames arrive over GVCP/GVSP identical to the
// simulated camera's own; a lossy link and a camera that goes away are clear errors, never a
// hang, and the camera is opened again when it comes back.
#include "hw/aravis/camera.h"

#include <gtest/gtest.h>

#include <chrono>

#include "insitu/sim/world.h"

namespace insitu::hw::aravis {
namespace {

// The fake camera serves the address of a local interface, one camera per address: these tests
// use 127.0.0.1 and run one at a time (ctest RESOURCE_LOCK gige_loopback).

// The default world's camera, cut to a sensor the fake camera serves.
sim::WorldOptions GigEWorld() {
  sim::WorldOptions w;
  w.camera.width_px = 640;
  w.camera.height_px = 480;
  w.camera.model = "Fake";
  w.camera.serial = "SIM-GV01";
  return w;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(Aravis, FramesOverGigEAreTheSimulatorsOwn) {
  auto served_world = std::make_shared<sim::SimWorld>(GigEWorld());
  sim::SimWorld reference(GigEWorld());
  auto served = SimulatedGigECamera::Start(served_world, "127.0.0.1", "SIM-GV01");
  ASSERT_TRUE(served.ok()) << served.status().ToString();
  CameraOptions o;
  o.device = "127.0.0.1";
  o.roi_width = 640;
  o.roi_height = 480;
  o.frame_timeout_ms = 3000.0;  // rendering on a loaded machine (see below)
  auto camera = OpenCamera(o);
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*camera)->info().model, "Fake");
  EXPECT_EQ((*camera)->info().serial, "SIM-GV01");
  EXPECT_EQ((*camera)->info().sensor_width_px, 640);
  ASSERT_TRUE((*camera)->SetExposure(20000.0).ok());
  ASSERT_TRUE(reference.SetExposure(20000.0).ok());
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d from(-5.0 + k, -30.0, 0.0), to(-5.0 + k, 30.0, 0.0);
    ASSERT_TRUE(served_world->StartPointerLine(from, to, 5000.0).ok());
    ASSERT_TRUE(reference.StartPointerLine(from, to, 5000.0).ok());
    auto frame = (*camera)->Grab();
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    auto expected = reference.Grab();
    ASSERT_TRUE(expected.ok());
    EXPECT_EQ(frame->width, 640);
    EXPECT_EQ(frame->height, 480);
    EXPECT_TRUE(frame->bytes == expected->bytes) << "frame " << k << " differs";
  }
  EXPECT_EQ((*served)->frames_rendered(), 3);
  // A region of interest over GigE: the band's rows of the same frame, where they lie, and the
  // simulated link's time for the band only.
  ASSERT_TRUE((*camera)->SetRegion(160, 96).ok());
  ASSERT_TRUE(reference.SetRegion(160, 96).ok());
  const double t0 = served_world->now_s();
  ASSERT_TRUE(served_world->StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000.0).ok());
  ASSERT_TRUE(reference.StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000.0).ok());
  auto band = (*camera)->Grab();
  ASSERT_TRUE(band.ok()) << band.status().ToString();
  auto expected = reference.Grab();
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(band->offset_y, 160);
  EXPECT_EQ(band->height, 96);
  EXPECT_TRUE(band->bytes == expected->bytes);
  EXPECT_NEAR(served_world->now_s() - t0, 0.02 + 640.0 * 96.0 / 118e6, 1e-9);
  EXPECT_EQ((*camera)->SetRegion(400, 200).code(), StatusCode::kOutOfRange);
  ASSERT_TRUE((*camera)->SetRegion(0, 0).ok());
  ASSERT_TRUE(served_world->StartPointerLine({0, -30, 0}, {0, 30, 0}, 5000.0).ok());
  auto whole = (*camera)->Grab();
  ASSERT_TRUE(whole.ok());
  EXPECT_EQ(whole->height, 480);
}

TEST(Aravis, ALossyLinkAndALostCameraAreErrorsAndTheCameraComesBack) {
  auto world = std::make_shared<sim::SimWorld>(GigEWorld());
  auto served = SimulatedGigECamera::Start(world, "127.0.0.1", "SIM-GV01");
  ASSERT_TRUE(served.ok()) << served.status().ToString();
  CameraOptions o;
  o.device = "127.0.0.1";
  o.roi_width = 640;
  o.roi_height = 480;
  // The served camera renders after the trigger, and CI runs other tests on both cores: 3 s
  // keeps a slow frame from passing for a lost one.
  o.frame_timeout_ms = 3000.0;
  auto camera = OpenCamera(o);
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  ASSERT_TRUE((*camera)->SetExposure(1000.0).ok());
  ASSERT_TRUE((*camera)->Grab().ok());

  // Every packet lost: the frame never completes; an error within the timeout, not a hang.
  (*served)->SetLostPacketRatio(1.0);
  auto t0 = std::chrono::steady_clock::now();
  const auto lossy = (*camera)->Grab();
  ASSERT_FALSE(lossy.ok());
  EXPECT_EQ(lossy.status().code(), StatusCode::kDeviceError);
  EXPECT_LT(Seconds(t0), 3.0 + 2.0);  // the timeout (exposure + 3 s), and teardown
  (*served)->SetLostPacketRatio(0.0);
  auto next = (*camera)->Grab();
  ASSERT_TRUE(next.ok()) << next.status().ToString();  // the link is good again

  // The camera goes away: a clear error; it comes back: the next grab opens it again.
  served->reset();
  t0 = std::chrono::steady_clock::now();
  const auto gone = (*camera)->Grab();
  ASSERT_FALSE(gone.ok());
  EXPECT_EQ(gone.status().code(), StatusCode::kDeviceError);
  // Bounded, not a hang: Aravis 0.8 tries a GVCP command 5 times with 500 ms each (the trigger);
  // the dead connection is released aside.
  EXPECT_LT(Seconds(t0), 8.0);  // 2.5 s of GVCP tries, with room for a loaded machine
  auto back = SimulatedGigECamera::Start(world, "127.0.0.1", "SIM-GV01");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  auto again = (*camera)->Grab();
  EXPECT_TRUE(again.ok()) << again.status().ToString();
}

TEST(Aravis, NoCameraIsAClearError) {
  CameraOptions o;
  o.device = "127.0.0.1";  // nothing serves it now
  const auto t0 = std::chrono::steady_clock::now();
  const auto camera = OpenCamera(o);
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kNotFound);
  EXPECT_NE(camera.status().message().find("127.0.0.1"), std::string::npos);
  EXPECT_LT(Seconds(t0), 10.0);
  // One camera per address: a second one on a served address is refused by name.
  auto world = std::make_shared<sim::SimWorld>(GigEWorld());
  auto first = SimulatedGigECamera::Start(world, "127.0.0.1", "A");
  ASSERT_TRUE(first.ok());
  const auto second = SimulatedGigECamera::Start(world, "127.0.0.1", "B");
  EXPECT_EQ(second.status().code(), StatusCode::kDeviceError);
  // A sensor the fake camera cannot serve.
  sim::WorldOptions big;  // 2448 x 2048
  EXPECT_EQ(SimulatedGigECamera::Start(std::make_shared<sim::SimWorld>(big), "127.0.0.2", "C")
                .status()
                .code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace insitu::hw::aravis
