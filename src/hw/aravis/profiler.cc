// A GenICam 3D line profiler through Aravis: one profile per frame (the range component, one
// line), decoded with the sensor's own Scan3d scale and offset, the encoder count from chunk
// data, and every failure of the link a clear device error; the sensor is opened again on the
// next grab when it comes back, as the camera backend does (camera.cc).
//
// Why the choices:
// - The geometry is read from the sensor, not configured: Width is the point count, the
//   CoordinateA scale and offset the X spacing and start (RectifiedC output), the CoordinateC
//   scale, offset and axis limits the range's count, zero and measuring range. A profile is
//   decoded with exactly what info() reports, so Profiler::Grab's check is a check of the link.
// - The encoder count must be the one latched with the exposure, so it comes from chunk data
//   (ArvChunkParser on the frame). A frame without chunk data can only be paired with a count
//   read back over GVCP when one frame at a time is in flight: with a software trigger, and
//   checked against ChunkFrameID when the sensor has it. Aravis 0.8's fake camera needs this
//   (sim_gige_profiler.cc says why); a real sensor that sends chunks never takes that path.
// - Frames left in the stream's queue before a trigger belong to earlier grabs (a frame that
//   came after its grab timed out): they are dropped, so a grab returns its own frame.
#include <arv.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <string>

#include "hw/aravis/gige_common.h"
#include "hw/aravis/profiler.h"
#include "insitu/core/log.h"

namespace insitu::hw::aravis {

namespace {

// One Scan3d coordinate: a transmitted value v is v * scale + offset, in mm.
struct Coordinate {
  double scale = 1.0;
  double offset = 0.0;
  bool has_invalid = false;
  double invalid = 0.0;  // the transmitted value that means "no data"
  bool has_axis = false;
  double axis_min = 0.0, axis_max = 0.0;
};

class AravisProfiler : public Profiler {
 public:
  explicit AravisProfiler(ProfilerOptions o) : options_(std::move(o)) {}
  ~AravisProfiler() override { Disconnect(); }

  // Errors: not_found (nothing answers), device_error (it answered, but: names the feature).
  Status Connect() {
    INSITU_ASSIGN_OR_RETURN(address_, FindDevice(options_.device, "profiler"));
    INSITU_RETURN_IF_ERROR(link_.Open(address_, "profiler"));
    Status s = Setup();
    if (s.ok()) s = link_.StartStream(options_.buffers, options_.socket_buffer_bytes);
    if (!s.ok()) {
      Disconnect();
      return Status(s.code(), "GigE profiler at " + address_ + ": " + s.message());
    }
    return Status::Ok();
  }

  ProfilerInfo info() const override { return info_; }

  Status SetExposure(double exposure_us) override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    GError* error = nullptr;
    double lo = 0, hi = 0;
    arv_camera_get_exposure_time_bounds(camera(), &lo, &hi, &error);
    if (error != nullptr) {
      return Status(StatusCode::kDeviceError,
                    "GigE profiler at " + address_ + ": exposure bounds: " + Take(&error));
    }
    if (!(exposure_us >= lo && exposure_us <= hi)) {
      return OutOfRange("exposure " + std::to_string(exposure_us) +
                        " us is outside the profiler's [" + std::to_string(lo) + ", " +
                        std::to_string(hi) + "] us");
    }
    arv_camera_set_exposure_time(camera(), exposure_us, &error);
    if (error != nullptr) return Lost("exposure: " + Take(&error));
    exposure_us_ = exposure_us;
    return Status::Ok();
  }

 protected:
  Result<RangeProfile> GrabProfile() override {
    INSITU_RETURN_IF_ERROR(EnsureConnected());
    while (ArvBuffer* old = arv_stream_try_pop_buffer(stream()))
      arv_stream_push_buffer(stream(), old);
    GError* error = nullptr;
    const bool hardware = options_.trigger != "software";
    if (!hardware) {
      arv_camera_software_trigger(camera(), &error);
      if (error != nullptr) return Lost("trigger: " + Take(&error), /*reachable=*/false);
    }
    const double wait_ms = exposure_us_ * 1e-3 + options_.frame_timeout_ms;
    ArvBuffer* buffer =
        arv_stream_timeout_pop_buffer(stream(), static_cast<guint64>(wait_ms * 1e3));
    if (buffer == nullptr && hardware) {
      // No pulse on the trigger input is not a lost sensor.
      return Status(StatusCode::kDeviceError,
                    "GigE profiler at " + address_ + ": no trigger pulse on " + options_.trigger +
                        " within " + std::to_string(static_cast<int>(wait_ms)) + " ms");
    }
    if (buffer == nullptr) {
      return Lost("no profile within " + std::to_string(static_cast<int>(wait_ms)) + " ms");
    }
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    if (status != ARV_BUFFER_STATUS_SUCCESS) {
      arv_stream_push_buffer(stream(), buffer);
      return Status(StatusCode::kDeviceError, "GigE profiler at " + address_ + ": frame " +
                                                  StatusName(status) + " (profile dropped)");
    }
    RangeProfile p;
    const guint64 frame_id = arv_buffer_get_frame_id(buffer);
    const bool chunked = arv_buffer_has_chunks(buffer);
    Status s = Decode(buffer, &p);
    if (s.ok() && chunked) {
      p.encoder = arv_chunk_parser_get_integer_value(parser_, buffer, "ChunkEncoderValue", &error);
      if (error != nullptr)
        s = DeviceError("ChunkEncoderValue in the frame's chunks: " + Take(&error));
    }
    arv_stream_push_buffer(stream(), buffer);
    if (s.ok() && !chunked) s = ReadLatchedEncoder(frame_id, &p.encoder);
    if (!s.ok()) {
      return Status(StatusCode::kDeviceError, "GigE profiler at " + address_ + ": frame " +
                                                  std::to_string(frame_id) + ": " + s.message());
    }
    p.sequence = Widen(frame_id);
    return p;
  }

 private:
  ArvCamera* camera() const { return link_.camera(); }
  ArvStream* stream() const { return link_.stream(); }

  // Everything but the stream; the caller prefixes the address and disconnects on an error.
  Status Setup() {
    GError* error = nullptr;
    const auto fail = [&](const std::string& what) {
      return DeviceError(what + ": " + Take(&error));
    };
    const char* model = arv_camera_get_model_name(camera(), &error);
    if (error != nullptr) return fail("DeviceModelName");
    const char* serial = arv_camera_get_device_serial_number(camera(), &error);
    if (error != nullptr) return fail("DeviceSerialNumber");
    info_ = ProfilerInfo();
    info_.model = model != nullptr ? model : "";
    info_.serial = serial != nullptr ? serial : "";

    INSITU_RETURN_IF_ERROR(SelectRangeComponent());
    arv_camera_set_string(camera(), "PixelFormat", options_.pixel_format.c_str(), &error);
    if (error != nullptr) return fail("PixelFormat " + options_.pixel_format);
    format_ = options_.pixel_format == "Coord3D_C16" ? ARV_PIXEL_FORMAT_COORD3D_C_16
                                                     : ARV_PIXEL_FORMAT_COORD3D_C_32F;
    // One profile per frame: Height is the number of profiles a frame carries.
    const gint64 height = arv_camera_get_integer(camera(), "Height", &error);
    if (error != nullptr) return fail("Height");
    if (height != 1) {
      arv_camera_set_integer(camera(), "Height", 1, &error);
      if (error != nullptr) return fail("Height 1 (one profile per frame)");
    }
    const gint64 width = arv_camera_get_integer(camera(), "Width", &error);
    if (error != nullptr) return fail("Width");
    if (width < 1) return DeviceError("Width is " + std::to_string(width) + ": no points");
    info_.points = static_cast<int>(width);

    INSITU_RETURN_IF_ERROR(RequireEntry("Scan3dDistanceUnit", {"Millimeter"}));
    INSITU_RETURN_IF_ERROR(RequireEntry("Scan3dOutputMode", {"RectifiedC", "RectifiedC_Linescan"}));
    INSITU_RETURN_IF_ERROR(ReadCoordinate("CoordinateA", &x_));
    INSITU_RETURN_IF_ERROR(ReadCoordinate("CoordinateC", &z_));
    if (!(x_.scale > 0) || !std::isfinite(x_.offset)) {
      return DeviceError("Scan3dCoordinateScale/Offset of CoordinateA (" +
                         std::to_string(x_.scale) + ", " + std::to_string(x_.offset) +
                         ") is not a point spacing > 0 and an X start");
    }
    if (!(std::abs(z_.scale) > 0) || !std::isfinite(z_.scale) || !std::isfinite(z_.offset)) {
      return DeviceError("Scan3dCoordinateScale of CoordinateC is " + std::to_string(z_.scale));
    }
    info_.x_start_mm = x_.offset;
    info_.x_spacing_mm = x_.scale;
    SetRange();

    INSITU_RETURN_IF_ERROR(
        link_.SetAcquisition(options_.trigger, options_.packet_size, &exposure_us_));
    if (arv_camera_is_feature_available(camera(), "AcquisitionFrameRate", &error)) {
      double lo = 0, hi = 0;
      arv_camera_get_float_bounds(camera(), "AcquisitionFrameRate", &lo, &hi, &error);
      if (error == nullptr) info_.max_rate_hz = hi;
    }
    g_clear_error(&error);  // the rate is information only
    return EnableEncoderChunk();
  }

  // A multi-component sensor (range, intensity, ...): the range alone, so a frame is one image.
  Status SelectRangeComponent() {
    GError* error = nullptr;
    if (!arv_camera_is_feature_available(camera(), "ComponentSelector", &error)) {
      g_clear_error(&error);
      return Status::Ok();  // a single-component device: its image is the range
    }
    guint n = 0;
    const char** entries =
        arv_camera_dup_available_enumerations_as_strings(camera(), "ComponentSelector", &n, &error);
    if (error != nullptr) return DeviceError("ComponentSelector: " + Take(&error));
    bool has_range = false;
    for (guint i = 0; i < n && error == nullptr; ++i) {
      const bool range = std::strcmp(entries[i], "Range") == 0;
      has_range = has_range || range;
      arv_camera_set_string(camera(), "ComponentSelector", entries[i], &error);
      if (error == nullptr &&
          arv_camera_is_feature_available(camera(), "ComponentEnable", nullptr)) {
        arv_camera_set_boolean(camera(), "ComponentEnable", range, &error);
      }
    }
    g_free(entries);
    if (error != nullptr) return DeviceError("ComponentSelector/ComponentEnable: " + Take(&error));
    if (!has_range) return DeviceError("ComponentSelector has no Range component");
    arv_camera_set_string(camera(), "ComponentSelector", "Range", &error);
    if (error != nullptr) return DeviceError("ComponentSelector Range: " + Take(&error));
    return Status::Ok();
  }

  // A feature the sensor may not have; where it has it, it must be (or be set to) one of
  // `accepted`, the first tried first.
  Status RequireEntry(const char* feature, std::initializer_list<const char*> accepted) {
    GError* error = nullptr;
    if (!arv_camera_is_feature_available(camera(), feature, &error)) {
      g_clear_error(&error);
      return Status::Ok();
    }
    const char* value = arv_camera_get_string(camera(), feature, &error);
    if (error != nullptr) return DeviceError(std::string(feature) + ": " + Take(&error));
    const std::string current = value != nullptr ? value : "";
    std::string names;
    for (const char* a : accepted) {
      if (current == a) return Status::Ok();
      names += (names.empty() ? "" : " or ") + std::string(a);
    }
    for (const char* a : accepted) {
      arv_camera_set_string(camera(), feature, a, &error);
      if (error == nullptr) return Status::Ok();
      g_clear_error(&error);
    }
    return DeviceError(std::string(feature) + " is " + current + " and cannot be set to " + names);
  }

  Status ReadCoordinate(const char* which, Coordinate* c) {
    GError* error = nullptr;
    const std::string name = std::string(" of ") + which;
    arv_camera_set_string(camera(), "Scan3dCoordinateSelector", which, &error);
    if (error != nullptr)
      return DeviceError(std::string("Scan3dCoordinateSelector ") + which + ": " + Take(&error));
    c->scale = arv_camera_get_float(camera(), "Scan3dCoordinateScale", &error);
    if (error != nullptr) return DeviceError("Scan3dCoordinateScale" + name + ": " + Take(&error));
    c->offset = arv_camera_get_float(camera(), "Scan3dCoordinateOffset", &error);
    if (error != nullptr) return DeviceError("Scan3dCoordinateOffset" + name + ": " + Take(&error));
    c->has_invalid = false;
    if (arv_camera_is_feature_available(camera(), "Scan3dInvalidDataFlag", nullptr)) {
      c->has_invalid = arv_camera_get_boolean(camera(), "Scan3dInvalidDataFlag", &error);
      if (error != nullptr)
        return DeviceError("Scan3dInvalidDataFlag" + name + ": " + Take(&error));
    }
    if (c->has_invalid) {
      c->invalid = arv_camera_get_float(camera(), "Scan3dInvalidDataValue", &error);
      if (error != nullptr) {
        return DeviceError("Scan3dInvalidDataValue" + name + ": " + Take(&error));
      }
    }
    c->has_axis = arv_camera_is_feature_available(camera(), "Scan3dAxisMin", nullptr) &&
                  arv_camera_is_feature_available(camera(), "Scan3dAxisMax", nullptr);
    if (c->has_axis) {
      c->axis_min = arv_camera_get_float(camera(), "Scan3dAxisMin", &error);
      if (error == nullptr) c->axis_max = arv_camera_get_float(camera(), "Scan3dAxisMax", &error);
      if (error != nullptr) return DeviceError("Scan3dAxisMin/Max" + name + ": " + Take(&error));
    }
    return Status::Ok();
  }

  // The measuring range and the size of one count of the output, from the CoordinateC features.
  void SetRange() {
    const bool c16 = format_ == ARV_PIXEL_FORMAT_COORD3D_C_16;
    if (z_.has_axis && z_.axis_max > z_.axis_min) {
      info_.z_min_mm = z_.axis_min;
      info_.z_max_mm = z_.axis_max;
    } else if (c16) {
      // Without axis limits: every count but the invalid one.
      const double top = z_.has_invalid && z_.invalid == 65535.0 ? 65534.0 : 65535.0;
      const double a = z_.offset, b = z_.offset + top * z_.scale;
      info_.z_min_mm = std::min(a, b);
      info_.z_max_mm = std::max(a, b);
    }
    if (c16) {
      info_.z_resolution_mm = std::abs(z_.scale);
    } else if (info_.z_max_mm > info_.z_min_mm) {
      // A float's step at the end of the range the sensor transmits: the output's "count".
      const double raw = std::max(std::abs((info_.z_min_mm - z_.offset) / z_.scale),
                                  std::abs((info_.z_max_mm - z_.offset) / z_.scale));
      const float f = static_cast<float>(raw);
      info_.z_resolution_mm =
          std::abs(z_.scale) * (std::nextafter(f, std::numeric_limits<float>::infinity()) - f);
    }
  }

  // SFNC names the selector entry EncoderValue; some sensors name it after the chunk feature.
  Status EnableEncoderChunk() {
    GError* error = nullptr;
    const bool chunks = arv_camera_are_chunks_available(camera(), &error);
    g_clear_error(&error);
    if (!chunks) {
      return DeviceError(
          "no chunk data (ChunkModeActive, ChunkSelector): the encoder count "
          "cannot travel with the profile");
    }
    const char* entry = nullptr;
    for (const char* e : {"EncoderValue", "ChunkEncoderValue"}) {
      if (arv_camera_is_enumeration_entry_available(camera(), "ChunkSelector", e, nullptr)) {
        entry = e;
        break;
      }
    }
    if (entry == nullptr) {
      return DeviceError(
          "ChunkSelector has no EncoderValue: the encoder count cannot travel "
          "with the profile");
    }
    arv_camera_set_chunk_mode(camera(), TRUE, &error);
    if (error != nullptr) return DeviceError("ChunkModeActive: " + Take(&error));
    arv_camera_set_chunk_state(camera(), entry, TRUE, &error);
    if (error != nullptr) {
      return DeviceError(std::string("ChunkSelector ") + entry + ", ChunkEnable: " + Take(&error));
    }
    has_chunk_frame_id_ = arv_camera_is_feature_available(camera(), "ChunkFrameID", nullptr);
    if (parser_ != nullptr) g_object_unref(parser_);
    parser_ = arv_camera_create_chunk_parser(camera());
    if (parser_ == nullptr) return DeviceError("no chunk parser for the device's GenICam file");
    return Status::Ok();
  }

  // A frame without chunk data: the count latched with it, read back from the device.
  Status ReadLatchedEncoder(guint64 frame_id, int64_t* encoder) {
    if (options_.trigger != "software") {
      return DeviceError(
          "no chunk data in the frame: with a hardware trigger the encoder "
          "count cannot be read back for it (ChunkModeActive is set; check the "
          "sensor's chunk settings)");
    }
    GError* error = nullptr;
    if (has_chunk_frame_id_) {
      const gint64 latched = arv_camera_get_integer(camera(), "ChunkFrameID", &error);
      if (error != nullptr) {
        return DeviceError(
            "no chunk data in the frame, and ChunkFrameID cannot be read from "
            "the device: " +
            Take(&error));
      }
      // GigE Vision 1.x frame ids are 16 bits wide.
      if ((static_cast<guint64>(latched) & 0xFFFF) != (frame_id & 0xFFFF)) {
        return DeviceError("the encoder count the device holds is frame " +
                           std::to_string(latched) + "'s, not this frame's");
      }
    }
    *encoder = arv_camera_get_integer(camera(), "ChunkEncoderValue", &error);
    if (error != nullptr) {
      return DeviceError(
          "no chunk data in the frame, and ChunkEncoderValue cannot be read from "
          "the device: " +
          Take(&error));
    }
    return Status::Ok();
  }

  // The range line of a frame, in mm; NaN where the sensor sent its invalid value.
  Status Decode(ArvBuffer* buffer, RangeProfile* p) const {
    const guint parts = arv_buffer_get_n_parts(buffer);
    guint part = parts;
    for (guint i = 0; i < parts; ++i) {
      if (arv_buffer_get_part_pixel_format(buffer, i) == format_) {
        part = i;
        break;
      }
    }
    if (part == parts) {
      return DeviceError(std::string("no ") + options_.pixel_format + " image in the frame " +
                         "(payload type " +
                         std::to_string(static_cast<int>(arv_buffer_get_payload_type(buffer))) +
                         ", " + std::to_string(parts) + " parts)");
    }
    const int width = arv_buffer_get_part_width(buffer, part);
    const int height = arv_buffer_get_part_height(buffer, part);
    if (width != info_.points || height < 1) {
      return DeviceError("a " + std::to_string(width) + " x " + std::to_string(height) +
                         " range image from a profiler of " + std::to_string(info_.points) +
                         " points");
    }
    const bool c16 = format_ == ARV_PIXEL_FORMAT_COORD3D_C_16;
    const size_t bytes = c16 ? 2 : 4;
    size_t size = 0;
    const auto* d = static_cast<const uint8_t*>(arv_buffer_get_part_data(buffer, part, &size));
    if (d == nullptr || size < bytes * width) {
      return DeviceError("a payload of " + std::to_string(size) + " bytes for " +
                         std::to_string(width) + " points");
    }
    p->x_start_mm = x_.offset;
    p->x_spacing_mm = x_.scale;
    p->timestamp_s = arv_buffer_get_timestamp(buffer) * 1e-9;
    p->z_mm.resize(width);
    // Pixel data is little-endian (PFNC), whatever the host.
    for (int i = 0; i < width; ++i) {
      const uint8_t* b = d + bytes * i;
      double raw = 0.0;
      bool invalid = false;
      if (c16) {
        raw = static_cast<double>(b[0] | (b[1] << 8));
      } else {
        const uint32_t bits =
            uint32_t{b[0]} | uint32_t{b[1]} << 8 | uint32_t{b[2]} << 16 | uint32_t{b[3]} << 24;
        float f = 0.0f;
        std::memcpy(&f, &bits, sizeof f);
        raw = f;
        invalid = !std::isfinite(f);
      }
      invalid = invalid || (z_.has_invalid && raw == z_.invalid);
      p->z_mm[i] = invalid ? std::numeric_limits<float>::quiet_NaN()
                           : static_cast<float>(raw * z_.scale + z_.offset);
    }
    return Status::Ok();
  }

  // GigE Vision 1.x block ids are 16 bits and skip 0 (65535 is followed by 1): the sequence
  // counts on across the wrap, frames lost between two profiles included.
  uint64_t Widen(guint64 frame_id) {
    if (!have_frame_id_) {
      sequence_ = frame_id;
    } else if (frame_id <= 0xFFFF && last_frame_id_ <= 0xFFFF) {
      sequence_ += (frame_id + 65535 - last_frame_id_) % 65535;
    } else {
      sequence_ += frame_id > last_frame_id_ ? frame_id - last_frame_id_ : 1;  // 64-bit ids
    }
    have_frame_id_ = true;
    last_frame_id_ = frame_id;
    return sequence_;
  }

  Status EnsureConnected() {
    if (camera() != nullptr) return Status::Ok();
    if (!options_.reconnect && lost_) {
      return Status(StatusCode::kDeviceError, "GigE profiler " + address_ + " was lost");
    }
    const ProfilerInfo before = info_;
    const Status s = Connect();
    if (!s.ok()) {
      return Status(StatusCode::kDeviceError, "GigE profiler " +
                                                  (address_.empty() ? options_.device : address_) +
                                                  " is not available: " + s.message());
    }
    if (lost_) Logger("hw")->info("GigE profiler at {} is back", address_);
    if (lost_ && (before.points != info_.points || before.x_spacing_mm != info_.x_spacing_mm ||
                  before.z_resolution_mm != info_.z_resolution_mm)) {
      Logger("hw")->warn("GigE profiler at {} came back with another geometry", address_);
    }
    lost_ = false;
    return Status::Ok();
  }

  // `reachable`: the sensor still answers; Connection::Close says why it matters.
  void Disconnect(bool reachable = true) {
    if (parser_ != nullptr) {
      g_object_unref(parser_);
      parser_ = nullptr;
    }
    link_.Close(reachable);
  }

  // The link failed: report it, drop the connection; the next grab reconnects.
  Status Lost(const std::string& what, bool reachable = true) {
    Logger("hw")->warn("GigE profiler at {}: {}; reconnecting on the next grab", address_, what);
    lost_ = true;
    Disconnect(reachable);
    return Status(StatusCode::kDeviceError, "GigE profiler at " + address_ + ": " + what);
  }

  ProfilerOptions options_;
  std::string address_;
  Connection link_;
  ArvChunkParser* parser_ = nullptr;
  ProfilerInfo info_;
  ArvPixelFormat format_ = ARV_PIXEL_FORMAT_COORD3D_C_16;
  Coordinate x_, z_;  // CoordinateA (X along the line), CoordinateC (range)
  bool has_chunk_frame_id_ = false;
  double exposure_us_ = 0.0;
  bool lost_ = false;
  bool have_frame_id_ = false;
  guint64 last_frame_id_ = 0;
  uint64_t sequence_ = 0;
};

}  // namespace

Result<std::unique_ptr<Profiler>> OpenProfiler(const ProfilerOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  auto profiler = std::make_unique<AravisProfiler>(options);
  INSITU_RETURN_IF_ERROR(profiler->Connect());
  return std::unique_ptr<Profiler>(std::move(profiler));
}

}  // namespace insitu::hw::aravis
