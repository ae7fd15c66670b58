// A GigE Vision camera through Aravis: software trigger, a pool of stream buffers, and every
// failure of the link (no frame in time, lost packets, a camera that stopped answering) a
// clear device error; the camera is opened again on the next grab when it comes back.
#include <arv.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "insitu/core/log.h"
#include "insitu/hw/aravis.h"

namespace insitu::hw::aravis {
namespace {

// Takes a GError's message and clears it.
std::string Take(GError** error) {
  std::string m = (*error != nullptr && (*error)->message != nullptr) ? (*error)->message : "?";
  g_clear_error(error);
  return m;
}

bool IsIpv4(const std::string& s) {
  int parts = 0, digits = 0;
  for (char c : s) {
    if (c == '.') {
      if (digits == 0) return false;
      ++parts;
      digits = 0;
    } else if (c >= '0' && c <= '9') {
      if (++digits > 3) return false;
    } else {
      return false;
    }
  }
  return parts == 3 && digits > 0;
}

const char* StatusName(ArvBufferStatus s) {
  switch (s) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "complete";
    case ARV_BUFFER_STATUS_CLEARED:
      return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "timed out waiting for its packets (packets lost)";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "missing packets";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "payload size mismatch";
    case ARV_BUFFER_STATUS_FILLING:
      return "still filling";
    case ARV_BUFFER_STATUS_ABORTED:
      return "aborted";
    default:
      return "unknown status";
  }
}

// The address of the camera the options name. Errors: not_found, invalid_argument.
Result<std::string> FindCamera(const std::string& device) {
  if (IsIpv4(device)) return device;
  arv_update_device_list();
  const unsigned n = arv_get_n_devices();
  std::vector<std::string> seen;
  std::vector<unsigned> gige;
  for (unsigned i = 0; i < n; ++i) {
    const char* protocol = arv_get_device_protocol(i);
    if (protocol == nullptr || std::string(protocol) != "GigEVision") continue;
    gige.push_back(i);
    const std::string id = arv_get_device_id(i) ? arv_get_device_id(i) : "";
    const std::string serial = arv_get_device_serial_nbr(i) ? arv_get_device_serial_nbr(i) : "";
    const std::string address = arv_get_device_address(i) ? arv_get_device_address(i) : "";
    seen.push_back(id + " (serial " + serial + ", " + address + ")");
    if (!device.empty() && (device == serial || device == id)) return address;
  }
  std::string list;
  for (const std::string& s : seen) list += (list.empty() ? "" : ", ") + s;
  if (device.empty()) {
    if (gige.size() == 1) return std::string(arv_get_device_address(gige[0]));
    if (gige.empty()) return NotFound("no GigE Vision camera found");
    return InvalidArgument("several GigE Vision cameras (" + list +
                           "): name one by serial, user id or address");
  }
  // A user id is not in the discovery reply: ask each camera.
  for (unsigned i : gige) {
    GError* error = nullptr;
    ArvCamera* c = arv_camera_new(arv_get_device_address(i), &error);
    if (c == nullptr) {
      g_clear_error(&error);
      continue;
    }
    std::string user;
    if (arv_camera_is_feature_available(c, "DeviceUserID", &error)) {
      const char* u = arv_camera_get_string(c, "DeviceUserID", &error);
      if (u != nullptr) user = u;
    }
    g_clear_error(&error);
    g_object_unref(c);
    if (user == device) return std::string(arv_get_device_address(i));
  }
  return NotFound("no GigE Vision camera '" + device + "'" +
                  (list.empty() ? std::string(" (none found)") : " (found: " + list + ")"));
}

class AravisCamera : public Camera {
 public:
  explicit AravisCamera(CameraOptions o) : options_(std::move(o)) {}
  ~AravisCamera() override {
    Disconnect();
    for (std::thread& t : teardown_) t.join();
  }

  Status Connect() {
    INSITU_ASSIGN_OR_RETURN(address_, FindCamera(options_.device));
    GError* error = nullptr;
    camera_ = arv_camera_new(address_.c_str(), &error);
    if (camera_ == nullptr) {
      return Status(StatusCode::kNotFound,
                    "GigE camera at " + address_ + " does not answer: " + Take(&error));
    }
    const auto fail = [&](const std::string& what) {
      const std::string m = "GigE camera at " + address_ + ": " + what + ": " + Take(&error);
      Disconnect();
      return Status(StatusCode::kDeviceError, m);
    };
    const char* model = arv_camera_get_model_name(camera_, &error);
    if (error != nullptr) return fail("model name");
    const char* serial = arv_camera_get_device_serial_number(camera_, &error);
    if (error != nullptr) return fail("serial number");
    int sw = 0, sh = 0;
    arv_camera_get_sensor_size(camera_, &sw, &sh, &error);
    if (error != nullptr) return fail("sensor size");
    info_.model = model ? model : "";
    info_.serial = serial ? serial : "";
    info_.sensor_width_px = options_.roi_width > 0 ? options_.roi_width : sw;
    info_.sensor_height_px = options_.roi_height > 0 ? options_.roi_height : sh;
    info_.bit_depth = options_.bit_depth;
    if (info_.sensor_width_px > sw || info_.sensor_height_px > sh) {
      error = nullptr;
      Disconnect();
      return InvalidArgument("GigE camera at " + address_ + ": a " +
                             std::to_string(info_.sensor_width_px) + " x " +
                             std::to_string(info_.sensor_height_px) + " region on a " +
                             std::to_string(sw) + " x " + std::to_string(sh) + " sensor");
    }
    arv_camera_set_pixel_format(camera_,
                                options_.bit_depth == 16   ? ARV_PIXEL_FORMAT_MONO_16
                                : options_.bit_depth == 12 ? ARV_PIXEL_FORMAT_MONO_12
                                                           : ARV_PIXEL_FORMAT_MONO_8,
                                &error);
    if (error != nullptr) return fail("pixel format");
    // The trigger is honoured on the camera's frame clock: run it fast. First: setting the
    // rate turns the trigger off on many cameras.
    double lo = 0, hi = 0;
    arv_camera_get_frame_rate_bounds(camera_, &lo, &hi, &error);
    if (error == nullptr) arv_camera_set_frame_rate(camera_, hi, &error);
    g_clear_error(&error);  // not every camera has a settable rate
    const bool software = options_.trigger == "software";
    arv_camera_set_trigger(camera_, software ? "Software" : options_.trigger.c_str(), &error);
    if (error != nullptr) return fail("trigger " + options_.trigger);
    arv_camera_gv_set_packet_size(camera_, options_.packet_size, &error);
    if (error != nullptr) return fail("packet size " + std::to_string(options_.packet_size));
    if (exposure_us_ > 0) {
      arv_camera_set_exposure_time(camera_, exposure_us_, &error);
      if (error != nullptr) return fail("exposure");
    } else {
      // Whatever the camera was left at: the grab timeout includes it.
      exposure_us_ = arv_camera_get_exposure_time(camera_, &error);
      if (error != nullptr) return fail("exposure");
    }
    // The binning this camera object works at (after a reconnect, the one it had): the
    // region below is set in binned pixels.
    if (const Status b = WriteBinning(binning_); !b.ok()) {
      Disconnect();
      return b;
    }
    arv_camera_set_gain(camera_, gain_db_, &error);
    if (error != nullptr) return fail("gain");
    return StartStream();
  }

  // `reachable`: the camera still answers (stop its acquisition first). A camera that stopped
  // answering costs a GVCP timeout per command (5 tries x 500 ms in Aravis 0.8), so none is
  // sent but the control release Aravis makes when the camera object goes.
  void Disconnect(bool reachable = true) {
    if (!reachable) {
      // Aravis's teardown of a device that stopped answering waits out its heartbeat and the
      // control release (about 10 s): done aside, so the grab that found the loss returns now.
      ArvStream* stream = stream_;
      ArvCamera* camera = camera_;
      stream_ = nullptr;
      camera_ = nullptr;
      teardown_.emplace_back([stream, camera] {
        if (stream != nullptr) g_object_unref(stream);
        if (camera != nullptr) g_object_unref(camera);
      });
      return;
    }
    StopStream(reachable);
    if (camera_ != nullptr) {
      g_object_unref(camera_);
      camera_ = nullptr;
    }
  }

  CameraInfo info() const override { return info_; }

  Status SetExposure(double exposure_us) override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_exposure_time_bounds(camera_, &lo, &hi, &error);
    if (error != nullptr)
      return Status(StatusCode::kDeviceError, "exposure bounds: " + Take(&error));
    if (!(exposure_us >= lo && exposure_us <= hi)) {
      return OutOfRange("exposure " + std::to_string(exposure_us) +
                        " us is outside the camera's [" + std::to_string(lo) + ", " +
                        std::to_string(hi) + "] us");
    }
    arv_camera_set_exposure_time(camera_, exposure_us, &error);
    if (error != nullptr) return Lost("exposure: " + Take(&error));
    exposure_us_ = exposure_us;
    return Status::Ok();
  }

  Status SetGain(double gain_db) override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_gain_bounds(camera_, &lo, &hi, &error);
    if (error != nullptr) return Status(StatusCode::kDeviceError, "gain bounds: " + Take(&error));
    if (!(gain_db >= lo && gain_db <= hi)) {
      return OutOfRange("gain " + std::to_string(gain_db) + " is outside the camera's [" +
                        std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
    arv_camera_set_gain(camera_, gain_db, &error);
    if (error != nullptr) return Lost("gain: " + Take(&error));
    gain_db_ = gain_db;
    return Status::Ok();
  }

  Status SetBinning(int binning) override {
    if (binning != 1 && binning != 2 && binning != 4) {
      return OutOfRange("binning " + std::to_string(binning) + " is not 1, 2 or 4");
    }
    if (binning == binning_) return Status::Ok();
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    StopStream();
    INSITU_RETURN_IF_ERROR(WriteBinning(binning));
    binning_ = binning;
    return StartStream();
  }

 protected:
  Result<Frame> GrabFrame() override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    if (options_.trigger == "software") {
      arv_camera_software_trigger(camera_, &error);
      if (error != nullptr) return Lost("trigger: " + Take(&error), /*reachable=*/false);
    }
    const bool hardware = options_.trigger != "software";
    if (hardware) {
      // Frames from pulses that came before this grab are not this grab's: drop them.
      while (ArvBuffer* old = arv_stream_try_pop_buffer(stream_)) arv_stream_push_buffer(stream_, old);
    }
    const double wait_ms = exposure_us_ * 1e-3 + options_.frame_timeout_ms;
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(stream_, static_cast<guint64>(wait_ms * 1e3));
    if (buffer == nullptr && hardware) {
      // No pulse on the trigger input is not a lost camera.
      return Status(StatusCode::kDeviceError,
                    "GigE camera at " + address_ + ": no trigger pulse on " + options_.trigger +
                        " within " + std::to_string(static_cast<int>(wait_ms)) + " ms");
    }
    if (buffer == nullptr) {
      // Nothing at all: the camera may be gone. Open it again on the next grab.
      return Lost("no frame within " + std::to_string(static_cast<int>(wait_ms)) + " ms");
    }
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    if (status != ARV_BUFFER_STATUS_SUCCESS) {
      arv_stream_push_buffer(stream_, buffer);
      return Status(StatusCode::kDeviceError,
                    "GigE camera at " + address_ + ": frame " + StatusName(status) + " (dropped)");
    }
    Frame f;
    f.width = arv_buffer_get_image_width(buffer);
    f.height = arv_buffer_get_image_height(buffer);
    f.bit_depth = options_.bit_depth;
    f.binning = binning_;
    f.sequence = arv_buffer_get_frame_id(buffer);
    f.timestamp_s = arv_buffer_get_timestamp(buffer) * 1e-9;
    f.exposure_us = exposure_us_;
    f.gain_db = gain_db_;
    size_t size = 0;
    const auto* data = static_cast<const uint8_t*>(arv_buffer_get_image_data(buffer, &size));
    f.bytes.assign(data, data + size);  // Camera::Grab checks the size against the header
    arv_stream_push_buffer(stream_, buffer);
    return f;
  }

 private:
  Status EnsureConnected() {
    if (camera_ != nullptr) return Status::Ok();
    if (!options_.reconnect && lost_) {
      return Status(StatusCode::kDeviceError, "GigE camera " + address_ + " was lost");
    }
    const Status s = Connect();
    if (!s.ok()) {
      return Status(StatusCode::kDeviceError, "GigE camera " +
                                                  (address_.empty() ? options_.device : address_) +
                                                  " is not available: " + s.message());
    }
    if (lost_) Logger("hw")->info("GigE camera at {} is back", address_);
    lost_ = false;
    return Status::Ok();
  }

  // Sets both binning features; a camera without them can only run unbinned.
  Status WriteBinning(int binning) {
    GError* error = nullptr;
    for (const char* feature : {"BinningHorizontal", "BinningVertical"}) {
      const bool available = arv_camera_is_feature_available(camera_, feature, &error);
      if (error != nullptr) return Lost(std::string(feature) + ": " + Take(&error));
      if (!available) {
        if (binning == 1) continue;
        return OutOfRange("GigE camera at " + address_ + " has no " + feature +
                          ": it cannot bin " + std::to_string(binning) + " x");
      }
      arv_camera_set_integer(camera_, feature, binning, &error);
      if (error != nullptr) return Lost(std::string(feature) + ": " + Take(&error));
    }
    return Status::Ok();
  }

  // The link failed: report it, drop the connection; the next grab reconnects.
  Status Lost(const std::string& what, bool reachable = true) {
    Logger("hw")->warn("GigE camera at {}: {}; reconnecting on the next grab", address_, what);
    lost_ = true;
    Disconnect(reachable);
    return Status(StatusCode::kDeviceError, "GigE camera at " + address_ + ": " + what);
  }

  Status StartStream() {
    GError* error = nullptr;
    const int w = info_.sensor_width_px / binning_, h = info_.sensor_height_px / binning_;
    arv_camera_set_region(camera_, 0, 0, w, h, &error);
    if (error != nullptr) return Lost("region: " + Take(&error));
    stream_ = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
    if (stream_ == nullptr) return Lost("stream: " + Take(&error));
    if (ARV_IS_GV_STREAM(stream_)) {
      g_object_set(stream_, "packet-resend", ARV_GV_STREAM_PACKET_RESEND_ALWAYS, "socket-buffer",
                   ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                   options_.socket_buffer_bytes, nullptr);
    }
    const guint payload = arv_camera_get_payload(camera_, &error);
    if (error != nullptr) return Lost("payload: " + Take(&error));
    for (int i = 0; i < options_.buffers; ++i) {
      arv_stream_push_buffer(stream_, arv_buffer_new(payload, nullptr));
    }
    arv_camera_start_acquisition(camera_, &error);
    if (error != nullptr) return Lost("acquisition start: " + Take(&error));
    return Status::Ok();
  }

  void StopStream(bool reachable = true) {
    if (stream_ == nullptr) return;
    GError* error = nullptr;
    if (camera_ != nullptr && reachable) arv_camera_stop_acquisition(camera_, &error);
    g_clear_error(&error);
    g_object_unref(stream_);
    stream_ = nullptr;
  }

  CameraOptions options_;
  std::string address_;
  ArvCamera* camera_ = nullptr;
  ArvStream* stream_ = nullptr;
  CameraInfo info_;
  int binning_ = 1;
  double exposure_us_ = 0.0;
  double gain_db_ = 0.0;
  bool lost_ = false;
  std::vector<std::thread> teardown_;  // lost connections being released
};

}  // namespace

Result<std::unique_ptr<Camera>> OpenCamera(const CameraOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  auto camera = std::make_unique<AravisCamera>(options);
  INSITU_RETURN_IF_ERROR(camera->Connect());
  return std::unique_ptr<Camera>(std::move(camera));
}

}  // namespace insitu::hw::aravis
