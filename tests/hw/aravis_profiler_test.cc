// The Aravis line-profiler backend against a real GigE Vision peer: a synthetic profiler served
// as a GenICam 3D device by Aravis's fake camera on a loopback address. Profiles arrive over
// GVCP/GVSP as the source made them, to the quantisation of the range; a lossy link and a sensor
// that goes away are clear errors, never a wrong profile or a hang, and the sensor is opened
// again when it comes back.
#include "hw/aravis/profiler.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <optional>

#include "hw/aravis/camera.h"
#include "insitu/sim/world.h"

namespace insitu::hw::aravis {
namespace {

// The fake camera serves the address of a local interface, one device per address: these tests
// use 127.0.0.1 and run one at a time (ctest RESOURCE_LOCK gige_loopback).
constexpr char kAddress[] = "127.0.0.1";

// A range in Coord3D_C16 is rounded to the nearest count of the source's 1 um: at most half a
// count off, plus the float the value is returned in (half an ulp at 10 mm: 4.8e-7 mm).
constexpr double kC16TolMm = 0.5 * 0.001 + 1e-6;

// A V-groove under a line profiler, the groove moving along the line from profile to profile,
// with a counting encoder: the bottom of the groove is occluded (NaN) and a few points drop out.
class GrooveSource : public Profiler {
 public:
  static ProfilerInfo Info() {
    ProfilerInfo i;
    i.model = "GrooveSim-640";
    i.serial = "G1";
    i.points = 640;
    i.x_start_mm = -16.0;
    i.x_spacing_mm = 0.05;
    i.z_min_mm = -10.0;
    i.z_max_mm = 10.0;
    i.z_resolution_mm = 0.001;
    i.max_rate_hz = 2000.0;
    return i;
  }
  static int64_t Encoder(int k) { return 1000 + 37 * int64_t{k}; }

  ProfilerInfo info() const override { return Info(); }

  Status SetExposure(double exposure_us) override {
    if (exposure_us < 10.0 || exposure_us > 50000.0) {
      return OutOfRange("exposure must be in [10, 50000] us");
    }
    std::lock_guard<std::mutex> lock(mutex_);
    exposure_us_ = exposure_us;
    return Status::Ok();
  }

  // The profile this source made with `encoder`, if it made one.
  std::optional<RangeProfile> Made(int64_t encoder) const {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = made_.find(encoder);
    if (it == made_.end()) return std::nullopt;
    return it->second;
  }
  double exposure_us() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return exposure_us_;
  }

 protected:
  // Runs on the fake camera's thread.
  Result<RangeProfile> GrabProfile() override {
    std::lock_guard<std::mutex> lock(mutex_);
    const ProfilerInfo info = Info();
    const int k = grabs_++;
    RangeProfile p;
    p.x_start_mm = info.x_start_mm;
    p.x_spacing_mm = info.x_spacing_mm;
    p.encoder = Encoder(k);
    p.sequence = k;
    p.z_mm.resize(info.points);
    const double centre_mm = -3.0 + 0.013 * k;
    for (int i = 0; i < info.points; ++i) {
      const double x = info.x_start_mm + i * info.x_spacing_mm;
      const double z = 4.0 - 0.45 * std::abs(x - centre_mm) + 0.0123 * std::sin(7.3 * x);
      const bool occluded = std::abs(x - centre_mm) < 0.25 || i % 53 == 7;
      p.z_mm[i] = occluded ? NAN : static_cast<float>(z);
    }
    made_[p.encoder] = p;
    return p;
  }

 private:
  mutable std::mutex mutex_;
  int grabs_ = 0;
  double exposure_us_ = 0.0;
  std::map<int64_t, RangeProfile> made_;
};

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// `got` is the source's profile with the same encoder count, point for point within `tol_mm`,
// NaN exactly where the source had NaN.
void ExpectSourcesProfile(const GrooveSource& source, const RangeProfile& got, double tol_mm) {
  const std::optional<RangeProfile> made = source.Made(got.encoder);
  ASSERT_TRUE(made.has_value()) << "encoder " << got.encoder << " is no profile of the source";
  EXPECT_DOUBLE_EQ(got.x_start_mm, made->x_start_mm);
  EXPECT_DOUBLE_EQ(got.x_spacing_mm, made->x_spacing_mm);
  ASSERT_EQ(got.z_mm.size(), made->z_mm.size());
  int nan = 0;
  for (size_t i = 0; i < got.z_mm.size(); ++i) {
    ASSERT_EQ(std::isnan(got.z_mm[i]), std::isnan(made->z_mm[i])) << "point " << i;
    if (std::isnan(made->z_mm[i])) {
      ++nan;
      continue;
    }
    ASSERT_NEAR(got.z_mm[i], made->z_mm[i], tol_mm) << "point " << i;
  }
  EXPECT_GT(nan, 10);  // the groove's bottom and the dropouts came through as NaN
}

// A source served on kAddress and a profiler opened on it. The profiler goes first, while its
// sensor still answers: closing one whose sensor is gone waits out GVCP timeouts.
struct Served {
  std::unique_ptr<SimulatedGigEProfiler> served;
  std::unique_ptr<Profiler> profiler;
};

// Serves `source` on kAddress and opens it with `o` (its device set to kAddress).
Result<Served> ServeAndOpen(std::shared_ptr<GrooveSource> source, ProfilerOptions o = {}) {
  auto served = SimulatedGigEProfiler::Start(std::move(source), kAddress, "SIM-P01");
  if (!served.ok()) return served.status();
  o.device = kAddress;
  auto profiler = OpenProfiler(o);
  if (!profiler.ok()) return profiler.status();
  return Served{std::move(*served), std::move(*profiler)};
}

TEST(AravisProfiler, ProfilesOverGigEAreTheSourcesOwn) {
  auto source = std::make_shared<GrooveSource>();
  auto link = ServeAndOpen(source);
  ASSERT_TRUE(link.ok()) << link.status().ToString();
  Profiler& profiler = *link->profiler;

  // The geometry is what the device's features say, which the simulator took from the source.
  const ProfilerInfo info = profiler.info();
  const ProfilerInfo truth = GrooveSource::Info();
  EXPECT_EQ(info.model, "GrooveSim-640");
  EXPECT_EQ(info.serial, "SIM-P01");
  EXPECT_EQ(info.points, truth.points);
  EXPECT_DOUBLE_EQ(info.x_start_mm, truth.x_start_mm);
  EXPECT_DOUBLE_EQ(info.x_spacing_mm, truth.x_spacing_mm);
  EXPECT_DOUBLE_EQ(info.z_min_mm, truth.z_min_mm);
  EXPECT_DOUBLE_EQ(info.z_max_mm, truth.z_max_mm);
  // 20 mm at 1 um is 20000 counts, within the 65535 of Coord3D_C16: the source's resolution.
  EXPECT_DOUBLE_EQ(info.z_resolution_mm, 0.001);
  EXPECT_DOUBLE_EQ(link->served->z_scale_mm(), 0.001);
  EXPECT_DOUBLE_EQ(info.max_rate_hz, truth.max_rate_hz);

  // The exposure goes over GVCP to the source; outside ExposureTime's bounds it is refused.
  ASSERT_TRUE(profiler.SetExposure(250.0).ok());
  EXPECT_EQ(profiler.SetExposure(5e6).code(), StatusCode::kOutOfRange);

  // Aravis's fake camera starts its 16-bit frame counter at 65400: 140 profiles cross its wrap,
  // and the sequence must count on by one.
  uint64_t last_sequence = 0;
  double last_timestamp_s = 0.0;
  for (int k = 0; k < 140; ++k) {
    auto p = profiler.Grab();
    ASSERT_TRUE(p.ok()) << "profile " << k << ": " << p.status().ToString();
    EXPECT_EQ(p->encoder, GrooveSource::Encoder(k));
    ExpectSourcesProfile(*source, *p, kC16TolMm);
    if (k > 0) {
      EXPECT_EQ(p->sequence, last_sequence + 1) << "profile " << k;
      EXPECT_GT(p->timestamp_s, last_timestamp_s);
    }
    last_sequence = p->sequence;
    last_timestamp_s = p->timestamp_s;
  }
  EXPECT_EQ(source->exposure_us(), 250.0);
  EXPECT_EQ(link->served->profiles_sent(), 140);
}

TEST(AravisProfiler, FloatRangesComeBackToFloatPrecision) {
  auto source = std::make_shared<GrooveSource>();
  ProfilerOptions o;
  o.pixel_format = "Coord3D_C32f";
  auto link = ServeAndOpen(source, o);
  ASSERT_TRUE(link.ok()) << link.status().ToString();
  Profiler& profiler = *link->profiler;
  // The transmitted value is (z - z_min) / 1 um, a float up to 20000: its step there is 2^-9
  // counts, 1.95e-6 mm at the 1 um scale, which info() reports as one count of the output.
  EXPECT_NEAR(profiler.info().z_resolution_mm, 0.001 * std::ldexp(1.0, -9), 1e-15);
  // Half that step for the float sent, half an ulp at 10 mm (4.8e-7) for the float returned.
  const double tol_mm = 0.5 * 0.001 * std::ldexp(1.0, -9) + 4.8e-7 + 1e-8;
  for (int k = 0; k < 3; ++k) {
    auto p = profiler.Grab();
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    EXPECT_EQ(p->encoder, GrooveSource::Encoder(k));
    ExpectSourcesProfile(*source, *p, tol_mm);
  }
}

TEST(AravisProfiler, ALossyLinkIsAnErrorNeverAWrongProfile) {
  auto source = std::make_shared<GrooveSource>();
  ProfilerOptions o;
  // 1280 bytes of profile in packets of 576: leader, three data packets, trailer. With a quarter
  // of the packets lost, a profile comes whole with probability 0.75^5 = 0.24.
  o.packet_size = 576;
  auto link = ServeAndOpen(source, o);
  ASSERT_TRUE(link.ok()) << link.status().ToString();
  Profiler& profiler = *link->profiler;
  auto first = profiler.Grab();
  ASSERT_TRUE(first.ok()) << first.status().ToString();

  link->served->SetLostPacketRatio(0.25);
  int errors = 0;
  RangeProfile last = *first;
  const auto t0 = std::chrono::steady_clock::now();
  for (int k = 0; k < 16; ++k) {
    auto p = profiler.Grab();
    if (!p.ok()) {
      EXPECT_EQ(p.status().code(), StatusCode::kDeviceError) << p.status().ToString();
      ++errors;
      continue;
    }
    ExpectSourcesProfile(*source, *p, kC16TolMm);  // whole: the source's
    // Each grab is one frame of the sensor and one count step of 37: the sequence counts the
    // frames lost in between.
    EXPECT_EQ(p->sequence - last.sequence, static_cast<uint64_t>((p->encoder - last.encoder) / 37));
    last = *p;
  }
  // 16 grabs, each lossless with probability 0.24: all whole with probability 1e-10.
  EXPECT_GT(errors, 0);
  EXPECT_LT(Seconds(t0), 16 * 1.2);  // each bounded by the frame timeout (1 s), no hang

  link->served->SetLostPacketRatio(0.0);
  auto next = profiler.Grab();
  ASSERT_TRUE(next.ok()) << next.status().ToString();  // the link is good again
  ExpectSourcesProfile(*source, *next, kC16TolMm);
}

TEST(AravisProfiler, ASensorThatGoesAwayIsAnErrorAndComesBack) {
  auto source = std::make_shared<GrooveSource>();
  auto link = ServeAndOpen(source);
  ASSERT_TRUE(link.ok()) << link.status().ToString();
  ASSERT_TRUE(link->profiler->Grab().ok());

  link->served.reset();
  auto t0 = std::chrono::steady_clock::now();
  const auto gone = link->profiler->Grab();
  ASSERT_FALSE(gone.ok());
  EXPECT_EQ(gone.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(gone.status().message().find("GigE profiler at 127.0.0.1"), std::string::npos)
      << gone.status().ToString();
  // Bounded: Aravis 0.8 tries the trigger command 5 times with 500 ms each (2.5 s); the dead
  // connection is released aside.
  EXPECT_LT(Seconds(t0), 8.0);

  auto back = SimulatedGigEProfiler::Start(source, kAddress, "SIM-P01");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  auto again = link->profiler->Grab();
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  ExpectSourcesProfile(*source, *again, kC16TolMm);
  // Closed while its sensor answers: closing one that is gone waits out GVCP timeouts.
  t0 = std::chrono::steady_clock::now();
  link->profiler.reset();
  EXPECT_LT(Seconds(t0), 8.0);  // the lost connection's release (done aside) is joined here
}

TEST(AravisProfiler, BadOptionsAndAbsentSensorsAreClearErrors) {
  const auto bad = [](auto change) {
    ProfilerOptions o;
    o.device = kAddress;
    change(o);
    return o.Validate();
  };
  EXPECT_NE(
      bad([](ProfilerOptions& o) { o.pixel_format = "Mono8"; }).message().find("pixel_format"),
      std::string::npos);
  EXPECT_NE(bad([](ProfilerOptions& o) { o.trigger = "Line7"; }).message().find("trigger"),
            std::string::npos);
  EXPECT_NE(bad([](ProfilerOptions& o) { o.packet_size = 100; }).message().find("packet_size"),
            std::string::npos);
  EXPECT_NE(bad([](ProfilerOptions& o) { o.buffers = 1; }).message().find("buffers"),
            std::string::npos);
  EXPECT_NE(bad([](ProfilerOptions& o) { o.frame_timeout_ms = 0; }).message().find("timeout"),
            std::string::npos);
  EXPECT_TRUE(bad([](ProfilerOptions&) {}).ok());
  ProfilerOptions invalid;
  invalid.trigger = "Line7";
  EXPECT_EQ(OpenProfiler(invalid).status().code(), StatusCode::kInvalidArgument);

  ProfilerOptions o;
  o.device = kAddress;  // nothing serves it now
  auto t0 = std::chrono::steady_clock::now();
  const auto none = OpenProfiler(o);
  EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
  EXPECT_NE(none.status().message().find("127.0.0.1"), std::string::npos);
  EXPECT_LT(Seconds(t0), 10.0);

  // Sources the simulator cannot serve, and one device per address.
  class Empty : public GrooveSource {
    ProfilerInfo info() const override { return ProfilerInfo(); }
  };
  EXPECT_EQ(SimulatedGigEProfiler::Start(std::make_shared<Empty>(), kAddress, "A").status().code(),
            StatusCode::kInvalidArgument);
  auto source = std::make_shared<GrooveSource>();
  EXPECT_EQ(SimulatedGigEProfiler::Start(source, kAddress, "SERIAL-OF-16-CHR").status().code(),
            StatusCode::kInvalidArgument);
  auto served = SimulatedGigEProfiler::Start(source, kAddress, "SIM-P01");
  ASSERT_TRUE(served.ok()) << served.status().ToString();
  EXPECT_EQ(SimulatedGigEProfiler::Start(source, kAddress, "B").status().code(),
            StatusCode::kDeviceError);

  // A hardware trigger that never comes: an error of its own, within the timeout.
  o.trigger = "Line0";
  o.frame_timeout_ms = 200.0;
  auto triggered = OpenProfiler(o);
  ASSERT_TRUE(triggered.ok()) << triggered.status().ToString();
  t0 = std::chrono::steady_clock::now();
  const auto no_pulse = (*triggered)->Grab();
  EXPECT_EQ(no_pulse.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(no_pulse.status().message().find("no trigger pulse on Line0"), std::string::npos)
      << no_pulse.status().ToString();
  EXPECT_LT(Seconds(t0), 2.0);
  triggered->reset();
  served->reset();

  // A 2D camera is not a profiler: the error names the feature it lacks.
  sim::WorldOptions w;
  w.camera.width_px = 64;
  w.camera.height_px = 48;
  auto camera = SimulatedGigECamera::Start(std::make_shared<sim::SimWorld>(w), kAddress, "C");
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  o.trigger = "software";
  const auto not_profiler = OpenProfiler(o);
  EXPECT_EQ(not_profiler.status().code(), StatusCode::kDeviceError);
  EXPECT_NE(not_profiler.status().message().find("PixelFormat Coord3D_C16"), std::string::npos)
      << not_profiler.status().ToString();
}

}  // namespace
}  // namespace insitu::hw::aravis
