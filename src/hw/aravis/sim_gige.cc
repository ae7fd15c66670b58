// Aravis's fake GigE Vision camera with the simulator behind it: each frame the fake camera
// sends is rendered by the world at the exposure, gain and binning the client set over GVCP.
#include <arv.h>

#include <atomic>
#include <cstring>
#include <mutex>

#include "hw/aravis/camera.h"
#include "hw/aravis/gige_common.h"
#include "insitu/core/log.h"
#include "insitu/sim/world.h"

namespace insitu::hw::aravis {

struct SimulatedGigECamera::Impl {
  std::shared_ptr<sim::SimWorld> world;
  std::string address;
  ArvGvFakeCamera* fake = nullptr;
  std::atomic<int> frames{0};

  // Runs on the fake camera's thread while the client waits for the frame it triggered.
  static void Fill(ArvBuffer* buffer, void* data, guint32 exposure_us, guint32 gain,
                   ArvPixelFormat format) {
    auto* self = static_cast<Impl*>(data);
    auto* out = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    const int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
    // The buffer reports no size here (Aravis 0.8): it holds the payload of w x h at the format.
    const size_t n = static_cast<size_t>(w) * h * ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format) / 8;
    if (out == nullptr) return;
    std::memset(out, 0, n);
    const auto& cam = self->world->options().camera;
    const int binning = w > 0 ? cam.width_px / w : 0;
    // A region of interest: the client's band of rows (OffsetY, Height), all columns.
    const int y = arv_buffer_get_image_y(buffer);
    if (format != ARV_PIXEL_FORMAT_MONO_8 || binning < 1 || cam.width_px / binning != w ||
        y < 0 || y + h > cam.height_px / binning) {
      Logger("sim")->error(
          "simulated GigE camera: a {} x {} frame at row {} (format {:#x}) is not a band of the "
          "{} x {} Mono8 sensor at binning 1, 2 or 4: sent black",
          w, h, y, static_cast<unsigned>(format), cam.width_px, cam.height_px);
      return;
    }
    sim::SimWorld& world = *self->world;
    const bool whole = h == cam.height_px / binning;
    Status s = world.SetBinning(binning);
    if (s.ok()) s = world.SetRegion(whole ? 0 : y * binning, whole ? 0 : h * binning);
    if (s.ok()) s = world.SetExposure(static_cast<double>(exposure_us));
    if (s.ok()) s = world.SetGain(static_cast<double>(gain));  // GainRaw taken as dB
    auto frame = s.ok() ? world.Grab() : Result<Frame>(s);
    if (!frame.ok() || frame->bytes.size() != n) {
      Logger("sim")->error("simulated GigE camera: {}",
                           frame.ok() ? "frame size" : frame.status().ToString());
      return;
    }
    std::memcpy(out, frame->bytes.data(), n);
    ++self->frames;
  }
};

SimulatedGigECamera::SimulatedGigECamera(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

SimulatedGigECamera::~SimulatedGigECamera() {
  if (impl_->fake != nullptr) g_object_unref(impl_->fake);  // joins its thread
}

Result<std::unique_ptr<SimulatedGigECamera>> SimulatedGigECamera::Start(
    std::shared_ptr<sim::SimWorld> world, const std::string& address, const std::string& serial) {
  const auto& cam = world->options().camera;
  if (cam.width_px > 2048 || cam.height_px > 2048) {
    return InvalidArgument(
        "the simulated GigE camera serves sensors up to 2048 x 2048, the world's "
        "camera is " +
        std::to_string(cam.width_px) + " x " + std::to_string(cam.height_px));
  }
  if (cam.bit_depth != 8) {
    return InvalidArgument(
        "the simulated GigE camera sends Mono8: the world's camera must be 8-bit");
  }
  INSITU_RETURN_IF_ERROR(CheckGvcpPortFree(address, "camera"));
  auto impl = std::make_unique<Impl>();
  impl->world = std::move(world);
  impl->address = address;
  impl->fake = arv_gv_fake_camera_new(address.c_str(), serial.c_str());
  if (impl->fake == nullptr || !arv_gv_fake_camera_is_running(impl->fake)) {
    if (impl->fake != nullptr) g_object_unref(impl->fake);
    impl->fake = nullptr;
    return Status(StatusCode::kDeviceError,
                  "cannot serve a GigE Vision camera on " + address + " (no such local address)");
  }
  arv_fake_camera_set_fill_pattern(arv_gv_fake_camera_get_fake_camera(impl->fake), &Impl::Fill,
                                   impl.get());
  return std::unique_ptr<SimulatedGigECamera>(new SimulatedGigECamera(std::move(impl)));
}

void SimulatedGigECamera::SetLostPacketRatio(double ratio) {
  g_object_set(impl_->fake, "gvsp-lost-ratio", ratio, nullptr);
}

const std::string& SimulatedGigECamera::address() const { return impl_->address; }

int SimulatedGigECamera::frames_rendered() const { return impl_->frames.load(); }

}  // namespace insitu::hw::aravis
