// A GigE Vision camera through Aravis: software trigger, a pool of stream buffers, and every
// failure of the link (no frame in time, lost packets, a camera that stopped answering) a
// clear device error; the camera is opened again on the next grab when it comes back.
#include <arv.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "hw/aravis/camera.h"
#include "hw/aravis/gige_common.h"
#include "insitu/core/log.h"

namespace insitu::hw::aravis {
namespace {

class AravisCamera : public Camera {
 public:
  explicit AravisCamera(CameraOptions o) : options_(std::move(o)) {}
  ~AravisCamera() override { Disconnect(); }

  Status Connect() {
    INSITU_ASSIGN_OR_RETURN(address_, FindDevice(options_.device, "camera"));
    INSITU_RETURN_IF_ERROR(link_.Open(address_, "camera"));
    GError* error = nullptr;
    const auto fail = [&](const std::string& what) {
      const std::string m = "GigE camera at " + address_ + ": " + what + ": " + Take(&error);
      Disconnect();
      return Status(StatusCode::kDeviceError, m);
    };
    const char* model = arv_camera_get_model_name(camera(), &error);
    if (error != nullptr) return fail("model name");
    const char* serial = arv_camera_get_device_serial_number(camera(), &error);
    if (error != nullptr) return fail("serial number");
    int sw = 0, sh = 0;
    arv_camera_get_sensor_size(camera(), &sw, &sh, &error);
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
    arv_camera_set_pixel_format(camera(),
                                options_.bit_depth == 16   ? ARV_PIXEL_FORMAT_MONO_16
                                : options_.bit_depth == 12 ? ARV_PIXEL_FORMAT_MONO_12
                                                           : ARV_PIXEL_FORMAT_MONO_8,
                                &error);
    if (error != nullptr) return fail("pixel format");
    // The trigger is honoured on the camera's frame clock: run it fast. First: setting the
    // rate turns the trigger off on many cameras.
    double lo = 0, hi = 0;
    arv_camera_get_frame_rate_bounds(camera(), &lo, &hi, &error);
    if (error == nullptr) arv_camera_set_frame_rate(camera(), hi, &error);
    g_clear_error(&error);  // not every camera has a settable rate
    // Software trigger for single grabs; a scan switches to the head's input (StartTriggered).
    const Status a = link_.SetAcquisition("software", options_.packet_size, &exposure_us_);
    if (!a.ok()) {
      Disconnect();
      return Status(a.code(), "GigE camera at " + address_ + ": " + a.message());
    }
    // The binning this camera object works at (after a reconnect, the one it had): the
    // region below is set in binned pixels.
    if (const Status b = WriteBinning(binning_); !b.ok()) {
      Disconnect();
      return b;
    }
    arv_camera_set_gain(camera(), gain_db_, &error);
    if (error != nullptr) return fail("gain");
    return StartStream();
  }

  // `reachable`: the camera still answers; Connection::Close says why it matters.
  void Disconnect(bool reachable = true) { link_.Close(reachable); }

  CameraInfo info() const override { return info_; }

  bool head_triggered() const override { return options_.trigger != "software"; }

  // The head's pulses on the wired input expose the frames; frames of earlier grabs still in
  // the stream's queue are dropped first, so the n-th grab is the n-th pulse's frame. The
  // trigger is set whole (mode off, FrameStart, source, rising edge, mode on): some cameras
  // refuse a new source while the trigger is on.
  Status StartTriggered() override {
    if (!head_triggered()) return Camera::StartTriggered();
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    DropQueuedFrames();
    GError* error = nullptr;
    arv_camera_set_trigger(camera(), options_.trigger.c_str(), &error);
    if (error != nullptr) return Lost("trigger source " + options_.trigger + ": " + Take(&error));
    triggered_ = true;
    last_frame_id_ = -1;
    return Status::Ok();
  }
  Status StopTriggered() override {
    if (!triggered_) return Status::Ok();
    triggered_ = false;
    if (camera() == nullptr) return Status::Ok();  // a reconnect comes back on software
    GError* error = nullptr;
    arv_camera_set_trigger(camera(), "Software", &error);
    // Frames of pulses after the last grab (a cancelled scan) are no single grab's.
    DropQueuedFrames();
    if (error != nullptr) return Lost("trigger source Software: " + Take(&error));
    return Status::Ok();
  }
  // The frame rate the camera says it reaches at its exposure, region and link
  // (ResultingFrameRate and its vendor names), else the bound of AcquisitionFrameRate (which
  // on some cameras ignores the exposure and the link); 0 without either.
  double max_frame_rate_hz() const override {
    if (camera() == nullptr) return 0.0;
    ArvDevice* device = arv_camera_get_device(camera());
    for (const char* name :
         {"ResultingFrameRate", "ResultingFrameRateAbs", "AcquisitionResultingFrameRate"}) {
      GError* error = nullptr;
      if (!arv_device_is_feature_available(device, name, &error) || error != nullptr) {
        g_clear_error(&error);
        continue;
      }
      const double rate = arv_device_get_float_feature_value(device, name, &error);
      if (error == nullptr && rate > 0 && std::isfinite(rate)) return rate;
      g_clear_error(&error);
    }
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_frame_rate_bounds(camera(), &lo, &hi, &error);
    if (error != nullptr) {
      g_clear_error(&error);
      return 0.0;
    }
    return hi > 0 && std::isfinite(hi) ? hi : 0.0;
  }

  Status SetExposure(double exposure_us) override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_exposure_time_bounds(camera(), &lo, &hi, &error);
    if (error != nullptr)
      return Status(StatusCode::kDeviceError, "exposure bounds: " + Take(&error));
    if (!(exposure_us >= lo && exposure_us <= hi)) {
      return OutOfRange("exposure " + std::to_string(exposure_us) +
                        " us is outside the camera's [" + std::to_string(lo) + ", " +
                        std::to_string(hi) + "] us");
    }
    arv_camera_set_exposure_time(camera(), exposure_us, &error);
    if (error != nullptr) return Lost("exposure: " + Take(&error));
    exposure_us_ = exposure_us;
    return Status::Ok();
  }

  Status SetGain(double gain_db) override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_gain_bounds(camera(), &lo, &hi, &error);
    if (error != nullptr) return Status(StatusCode::kDeviceError, "gain bounds: " + Take(&error));
    if (!(gain_db >= lo && gain_db <= hi)) {
      return OutOfRange("gain " + std::to_string(gain_db) + " is outside the camera's [" +
                        std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
    arv_camera_set_gain(camera(), gain_db, &error);
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
    link_.StopStream();
    INSITU_RETURN_IF_ERROR(WriteBinning(binning));
    binning_ = binning;
    return StartStream();
  }

  Status ApplyRegion(int first_row, int rows) override {
    if (first_row == region_first_row_ && rows == region_rows_) return Status::Ok();
    // Stored first: a camera reconnected later comes back with the region asked for last (the
    // whole sensor after a scan, even if the camera was away when it asked).
    region_first_row_ = rows == 0 ? 0 : first_row;
    region_rows_ = rows;
    if (camera() == nullptr) return EnsureConnected();
    if (rows > 0) {
      GError* error = nullptr;
      const bool offsets = arv_camera_is_region_offset_available(camera(), &error);
      g_clear_error(&error);
      if (!offsets) {
        region_first_row_ = region_rows_ = 0;
        return FailedPrecondition("GigE camera at " + address_ +
                                  " has no OffsetY: it cannot read a band of its sensor");
      }
    }
    link_.StopStream();
    const Status started = StartStream();
    if (!started.ok() && rows > 0) {
      // Refused: never keep a band the camera will not read; the next grab reconnects whole.
      region_first_row_ = region_rows_ = 0;
    }
    return started;
  }

 protected:
  Result<Frame> GrabFrame() override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    if (!triggered_) {
      DropQueuedFrames();  // a frame still queued is an earlier trigger's, not this grab's
      arv_camera_software_trigger(camera(), &error);
      if (error != nullptr) return Lost("trigger: " + Take(&error), /*reachable=*/false);
    }
    const double wait_ms = exposure_us_ * 1e-3 + options_.frame_timeout_ms;
    ArvBuffer* buffer =
        arv_stream_timeout_pop_buffer(stream(), static_cast<guint64>(wait_ms * 1e3));
    if (buffer == nullptr && triggered_) {
      // No pulse on the trigger input is not a lost camera.
      return Status(StatusCode::kDeviceError,
                    "GigE camera at " + address_ + ": no frame from a pulse on " +
                        options_.trigger + " within " + std::to_string(static_cast<int>(wait_ms)) +
                        " ms");
    }
    if (buffer == nullptr) {
      // Nothing at all: the camera may be gone. Open it again on the next grab.
      return Lost("no frame within " + std::to_string(static_cast<int>(wait_ms)) + " ms");
    }
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    if (status != ARV_BUFFER_STATUS_SUCCESS) {
      arv_stream_push_buffer(stream(), buffer);
      return Status(StatusCode::kDeviceError,
                    "GigE camera at " + address_ + ": frame " + StatusName(status) + " (dropped)");
    }
    Frame f;
    f.width = arv_buffer_get_image_width(buffer);
    f.height = arv_buffer_get_image_height(buffer);
    f.offset_x = arv_buffer_get_image_x(buffer);
    f.offset_y = arv_buffer_get_image_y(buffer);
    f.bit_depth = options_.bit_depth;
    f.binning = binning_;
    f.sequence = arv_buffer_get_frame_id(buffer);
    if (triggered_) {
      // Frame ids count exposures: a gap is a pulse the camera ignored or a frame the stream
      // lost, and every later frame would belong to another line.
      const auto id = static_cast<int64_t>(f.sequence);
      const int64_t expected = last_frame_id_ < 0 ? id : last_frame_id_ + 1;
      last_frame_id_ = id;
      if (id != expected && !(expected == 65536 && id == 1) && !(expected == 65536 && id == 0)) {
        arv_stream_push_buffer(stream(), buffer);
        return Status(StatusCode::kDeviceError,
                      "GigE camera at " + address_ + ": frame " + std::to_string(id) +
                          " follows frame " + std::to_string(expected - 1) +
                          ": a pulse was ignored or a frame lost, the lines would shift");
      }
    }
    f.timestamp_s = arv_buffer_get_timestamp(buffer) * 1e-9;
    f.exposure_us = exposure_us_;
    f.gain_db = gain_db_;
    size_t size = 0;
    const auto* data = static_cast<const uint8_t*>(arv_buffer_get_image_data(buffer, &size));
    f.bytes.assign(data, data + size);  // Camera::Grab checks the size against the header
    arv_stream_push_buffer(stream(), buffer);
    return f;
  }

 private:
  ArvCamera* camera() const { return link_.camera(); }
  ArvStream* stream() const { return link_.stream(); }
  bool triggered_ = false;  // between StartTriggered and StopTriggered
  int64_t last_frame_id_ = -1;  // the last triggered frame's id

  void DropQueuedFrames() {
    if (stream() == nullptr) return;
    while (ArvBuffer* old = arv_stream_try_pop_buffer(stream())) arv_stream_push_buffer(stream(), old);
  }

  Status EnsureConnected() {
    if (camera() != nullptr) return Status::Ok();
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
      const bool available = arv_camera_is_feature_available(camera(), feature, &error);
      if (error != nullptr) return Lost(std::string(feature) + ": " + Take(&error));
      if (!available) {
        if (binning == 1) continue;
        return OutOfRange("GigE camera at " + address_ + " has no " + feature +
                          ": it cannot bin " + std::to_string(binning) + " x");
      }
      arv_camera_set_integer(camera(), feature, binning, &error);
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
    const int w = info_.sensor_width_px / binning_, full_h = info_.sensor_height_px / binning_;
    int y = 0, h = full_h;
    if (region_rows_ > 0) {
      // The band in binned rows, widened to the camera's increments (a camera without them
      // takes any row).
      const int dy = std::max(1, static_cast<int>(arv_camera_get_y_offset_increment(camera(), &error)));
      g_clear_error(&error);
      const int dh = std::max(1, static_cast<int>(arv_camera_get_height_increment(camera(), &error)));
      g_clear_error(&error);
      y = region_first_row_ / binning_ / dy * dy;
      const int end = std::min(full_h, (region_first_row_ + region_rows_ + binning_ - 1) / binning_);
      h = std::min(full_h - y, (end - y + dh - 1) / dh * dh);
    }
    arv_camera_set_region(camera(), 0, y, w, h, &error);
    if (error != nullptr) return Lost("region: " + Take(&error));
    if (region_rows_ > 0) {
      // What the camera took: it must hold the band's rows (a camera may clip or ignore).
      int gx = 0, gy = 0, gw = 0, gh = 0;
      arv_camera_get_region(camera(), &gx, &gy, &gw, &gh, &error);
      if (error != nullptr) return Lost("region: " + Take(&error));
      const int end = std::min(full_h, (region_first_row_ + region_rows_ + binning_ - 1) / binning_);
      if (gy > region_first_row_ / binning_ || gy + gh < end) {
        const std::string why = "GigE camera at " + address_ + " took rows " +
                                std::to_string(gy) + ".." + std::to_string(gy + gh) +
                                " for the band " + std::to_string(region_first_row_ / binning_) +
                                ".." + std::to_string(end);
        region_first_row_ = region_rows_ = 0;  // the whole sensor, as before the request
        arv_camera_set_region(camera(), 0, 0, w, full_h, &error);
        if (error != nullptr) return Lost("region: " + Take(&error));
        const Status s = link_.StartStream(options_.buffers, options_.socket_buffer_bytes);
        return s.ok() ? FailedPrecondition(why) : Lost(s.message());
      }
    }
    const Status s = link_.StartStream(options_.buffers, options_.socket_buffer_bytes);
    return s.ok() ? s : Lost(s.message());
  }

  CameraOptions options_;
  std::string address_;
  Connection link_;
  CameraInfo info_;
  int binning_ = 1;
  int region_first_row_ = 0, region_rows_ = 0;  // full-sensor rows; 0 rows: the whole sensor
  double exposure_us_ = 0.0;
  double gain_db_ = 0.0;
  bool lost_ = false;
};

}  // namespace

Result<std::unique_ptr<Camera>> OpenCamera(const CameraOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  auto camera = std::make_unique<AravisCamera>(options);
  INSITU_RETURN_IF_ERROR(camera->Connect());
  return std::unique_ptr<Camera>(std::move(camera));
}

}  // namespace insitu::hw::aravis
