// Any hw::Profiler served as a GenICam 3D line profiler: Aravis's fake GigE Vision camera with
// a profiler's register map (ProfilerXml below), each triggered frame filled with one profile
// of the source.
//
// How the fake camera is bent to a profiler, and where it cannot be (Aravis 0.8.26):
// - The register map is ours: arv_gv_fake_camera_new_full reads any GenICam file and serves it
//   from its memory. The file is written from the binary into a memfd, so there is no runtime
//   path and nothing on disk. Our features are in the manufacturer-specific register space
//   (0xA000 up); the fake camera's own registers (width 0x100, height 0x104, pixel format
//   0x128, exposure 0x120, trigger 0x300..0x30c, acquisition 0x124) keep their addresses, since
//   the fake camera computes the payload and runs the trigger from them.
// - Chunk data: the fake camera always sends a GVSP leader and trailer of payload type 0x0001
//   (image), and Aravis's receiver marks a buffer as carrying chunks only from bit 0x4000 of the
//   leader's payload type (or type 0x0004); the fill callback cannot change either, and a
//   buffer's chunk flag has no public setter. So no payload layout written here could reach
//   ArvChunkParser. The honest fallback: ChunkEncoderValue and ChunkFrameID are served as device
//   registers, written here with each profile before its frame is sent; the backend reads them
//   over GVCP when a frame comes without chunks, checks ChunkFrameID against the frame, and
//   does so with a software trigger only (one frame in flight, so the registers hold this
//   frame's). A real sensor's chunks go through ArvChunkParser.
// - A profile that cannot be made is dropped: the fill cannot stop the frame, so it sets the
//   fake camera's packet loss to 1 for that frame (restored on the next fill).
#include <arv.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <string>
#include <utility>

#include "hw/aravis/gige_common.h"
#include "hw/aravis/profiler.h"
#include "insitu/core/log.h"

namespace insitu::hw::aravis {
namespace {

// GigE Vision bootstrap registers (GigE Vision 2.0, table 28): strings the client reads.
constexpr guint32 kManufacturerName = 0x48;  // 32 bytes
constexpr guint32 kModelName = 0x68;         // 32 bytes
constexpr guint32 kSerialNumber = 0xD8;      // 16 bytes
constexpr guint32 kUserDefinedName = 0xE8;   // 16 bytes

// The fake camera's own registers (arvfakecamera.h), which it acts on.
constexpr guint32 kSensorWidth = 0x11C;
constexpr guint32 kSensorHeight = 0x118;
constexpr guint32 kWidth = 0x100;
constexpr guint32 kHeight = 0x104;
constexpr guint32 kPixelFormat = 0x128;
constexpr guint32 kExposureUs = 0x120;

// Ours, as ProfilerXml declares them. Per-coordinate registers are indexed by
// Scan3dCoordinateSelector (CoordinateA 0, CoordinateC 2).
constexpr guint32 kCoordinateScale = 0xA010;    // f64 x 3
constexpr guint32 kCoordinateOffset = 0xA030;   // f64 x 3
constexpr guint32 kAxisMin = 0xA050;            // f64 x 3
constexpr guint32 kAxisMax = 0xA070;            // f64 x 3
constexpr guint32 kInvalidFlag = 0xA090;        // u32 x 3
constexpr guint32 kInvalidValue = 0xA0A0;       // f64 x 3
constexpr guint32 kChunkEncoderValue = 0xA0D0;  // i64
constexpr guint32 kChunkFrameId = 0xA0D8;       // u64
constexpr guint32 kFrameRateMax = 0xA0E0;       // f64
constexpr guint32 kComponentEnable = 0xA0E8;    // u32
constexpr int kA = 0, kC = 2;

constexpr guint32 kInvalidCount = 65535;  // Coord3D_C16; counts 0..65534 are ranges
constexpr int kMaxPoints = 16384;

// The register map as GenICam XML (GenApi schema 1.1), built from the addresses above (those
// of registers nothing here writes stand where they are declared): SFNC names and PFNC values.
// Chunk, Scan3d and component features follow SFNC 2.x; Scan3dOutputMode RectifiedC: the range of
// point i is at X = offset_A + i scale_A.
constexpr char kXmlHead[] = R"XML(<?xml version="1.0" encoding="utf-8"?>
<RegisterDescription ModelName="InsituSimulatedProfiler" VendorName="insitu"
    StandardNameSpace="GEV" SchemaMajorVersion="1" SchemaMinorVersion="1" SchemaSubMinorVersion="0"
    MajorVersion="1" MinorVersion="0" SubMinorVersion="0" ToolTip="insitu simulated line profiler"
    ProductGuid="4F1B6C6E-2D55-4A55-9A37-6A6E10000001"
    VersionGuid="4F1B6C6E-2D55-4A55-9A37-6A6E10000002"
    xmlns="http://www.genicam.org/GenApi/Version_1_1"
    xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:schemaLocation="http://www.genicam.org/GenApi/Version_1_1 GenApiSchema_Version_1_1.xsd">
)XML";

// PayloadSize: Width x Height pixels of the PixelFormat's bits (PFNC: bits 16..23).
constexpr char kXmlTail[] = R"XML(  <IntSwissKnife Name="PayloadSize" NameSpace="Standard">
    <pVariable Name="WIDTH">Width</pVariable>
    <pVariable Name="HEIGHT">Height</pVariable>
    <pVariable Name="PIXELFORMAT">PixelFormatReg</pVariable>
    <Formula>WIDTH * HEIGHT * ((PIXELFORMAT &gt;&gt; 16) &amp; 0xFF) / 8</Formula>
  </IntSwissKnife>
  <Port Name="Device" NameSpace="Standard"/>
</RegisterDescription>
)XML";

std::string Element(const std::string& tag, const std::string& value) {
  return "<" + tag + ">" + value + "</" + tag + ">";
}

// A node of the map, one a line: `type` ("Integer", "IntReg", ...) with `inside` its elements.
// Standard: an SFNC feature; Custom: ours (the registers and constants behind them).
std::string Node(const std::string& type, const std::string& name, const std::string& inside,
                 const char* name_space = "Standard") {
  return "  <" + type + " Name=\"" + name + "\" NameSpace=\"" + name_space + "\">" + inside + "</" +
         type + ">\n";
}

// Where a register is in the device's memory: `length` bytes at `address`, or, indexed by the
// register `index` names, at address + length x its value.
std::string Memory(guint32 address, int length, const char* access, const char* index) {
  char hex[16];
  std::snprintf(hex, sizeof hex, "0x%X", static_cast<unsigned>(address));
  std::string s = Element("Address", hex);
  if (index != nullptr) {
    s += "<pIndex Offset=\"" + std::to_string(length) + "\">" + index + "</pIndex>";
  }
  return s + Element("Length", std::to_string(length)) + Element("AccessMode", access) +
         Element("pPort", "Device");
}

// A string register: `length` bytes, NUL-padded.
std::string StringReg(const std::string& name, guint32 address, int length, const char* access) {
  return Node("StringReg", name, Memory(address, length, access, nullptr));
}

// An integer register, big-endian as GigE Vision's are.
struct IntRegister {
  guint32 address = 0;
  const char* access = "RW";
  const char* index = nullptr;  // the selector register it is indexed by
  int length = 4;
  const char* sign = "Unsigned";
  bool cached = true;  // false: read from the device each time (it changes by itself)
};

std::string IntReg(const std::string& name, const IntRegister& r, const char* name_space) {
  const std::string cache = r.cached ? "" : Element("Cachable", "NoCache");
  return Node("IntReg", name,
              Memory(r.address, r.length, r.access, r.index) + cache + Element("Sign", r.sign) +
                  Element("Endianess", "BigEndian"),
              name_space);
}

// A read-only f64 register, big-endian.
std::string FloatReg(const std::string& name, guint32 address, const char* index,
                     const char* name_space) {
  return Node("FloatReg", name, Memory(address, 8, "RO", index) + Element("Endianess", "BigEndian"),
              name_space);
}

// A chunk value served as a device register (the opening comment says why): 8 bytes, never
// cached, since it changes with each profile.
std::string ChunkRegister(const std::string& name, guint32 address, const char* sign) {
  const IntRegister r{
      .address = address, .access = "RO", .length = 8, .sign = sign, .cached = false};
  return IntReg(name, r, "Standard");
}

// A category: the features a client lists under `name`.
std::string Category(const std::string& name, std::initializer_list<const char*> features) {
  std::string inside;
  for (const char* f : features) inside += Element("pFeature", f);
  return Node("Category", name, inside);
}

using Entries = std::initializer_list<std::pair<const char*, guint32>>;

std::string Enumeration(const std::string& name, Entries entries, const std::string& value) {
  std::string inside;
  for (const auto& [entry, v] : entries) {
    inside += "<EnumEntry Name=\"" + std::string(entry) + "\" NameSpace=\"Standard\">" +
              Element("Value", std::to_string(v)) + "</EnumEntry>";
  }
  return Node("Enumeration", name, inside + Element("pValue", value));
}

// An enumeration with one entry, which it always has: its value is a constant, <name>Value.
std::string FixedEnumeration(const std::string& name, const char* entry, guint32 value) {
  return Enumeration(name, {{entry, value}}, name + "Value") +
         Node("Integer", name + "Value", Element("Value", std::to_string(value)), "Custom");
}

// An enumeration the device holds in a register of its own, <name>Reg.
std::string RegisterEnumeration(const std::string& name, Entries entries, guint32 address) {
  return Enumeration(name, entries, name + "Reg") + IntReg(name + "Reg", {address}, "Custom");
}

// A boolean the device holds in <name>Reg, 1 for on.
std::string RegisterBoolean(const std::string& name, const IntRegister& reg) {
  const std::string inside =
      Element("pValue", name + "Reg") + Element("OnValue", "1") + Element("OffValue", "0");
  return Node("Boolean", name, inside) + IntReg(name + "Reg", reg, "Custom");
}

// Commands, each writing its value to the one write-only register `reg`.
std::string Commands(const std::string& reg, guint32 address, Entries commands) {
  std::string s;
  for (const auto& [name, value] : commands) {
    s += Node("Command", name,
              Element("pValue", reg) + Element("CommandValue", std::to_string(value)));
  }
  return s + IntReg(reg, {.address = address, .access = "WO"}, "Custom");
}

std::string ProfilerXml() {
  const char* coordinate = "Scan3dCoordinateSelectorReg";
  std::string x = kXmlHead;
  x += Category("Root", {"DeviceControl", "ImageFormatControl", "AcquisitionControl",
                         "Scan3dControl", "ChunkDataControl", "TransportLayerControl"});

  x += Category("DeviceControl",
                {"DeviceVendorName", "DeviceModelName", "DeviceSerialNumber", "DeviceUserID"});
  x += StringReg("DeviceVendorName", kManufacturerName, 32, "RO");
  x += StringReg("DeviceModelName", kModelName, 32, "RO");
  x += StringReg("DeviceSerialNumber", kSerialNumber, 16, "RO");
  x += StringReg("DeviceUserID", kUserDefinedName, 16, "RW");

  x += Category("ImageFormatControl",
                {"ComponentSelector", "ComponentEnable", "SensorWidth", "SensorHeight", "Width",
                 "Height", "OffsetX", "OffsetY", "PixelFormat"});
  x += FixedEnumeration("ComponentSelector", "Range", 4);
  x += RegisterBoolean("ComponentEnable", {kComponentEnable});
  x += IntReg("SensorWidth", {.address = kSensorWidth, .access = "RO"}, "Standard");
  x += IntReg("SensorHeight", {.address = kSensorHeight, .access = "RO"}, "Standard");
  x += IntReg("Width", {.address = kWidth, .access = "RO"}, "Standard");
  x += Node("Integer", "Height",
            Element("pValue", "HeightReg") + Element("Min", "1") + Element("Max", "1") +
                Element("Inc", "1"));
  x += IntReg("HeightReg", {kHeight}, "Custom");
  for (const char* offset : {"OffsetX", "OffsetY"}) {
    x += Node("Integer", offset, Element("Value", "0") + Element("Min", "0") + Element("Max", "0"));
  }
  x += RegisterEnumeration("PixelFormat",
                           {{"Coord3D_C16", ARV_PIXEL_FORMAT_COORD3D_C_16},
                            {"Coord3D_C32f", ARV_PIXEL_FORMAT_COORD3D_C_32F}},
                           kPixelFormat);

  x += Category("AcquisitionControl",
                {"AcquisitionMode", "AcquisitionStart", "AcquisitionStop", "AcquisitionFrameRate",
                 "TriggerSelector", "TriggerMode", "TriggerSource", "TriggerActivation",
                 "TriggerSoftware", "ExposureTime"});
  x += RegisterEnumeration("AcquisitionMode", {{"Continuous", 1}}, 0x12C);
  x += Commands("AcquisitionReg", 0x124, {{"AcquisitionStart", 1}, {"AcquisitionStop", 0}});
  x += Node("Float", "AcquisitionFrameRate",
            Element("pValue", "FrameRateMaxReg") + Element("Min", "0") +
                Element("pMax", "FrameRateMaxReg") + Element("Unit", "Hz"));
  x += FloatReg("FrameRateMaxReg", kFrameRateMax, nullptr, "Custom");
  x += FixedEnumeration("TriggerSelector", "FrameStart", 0);
  x += RegisterEnumeration("TriggerMode", {{"Off", 0}, {"On", 1}}, 0x300);
  x += RegisterEnumeration("TriggerSource", {{"Line0", 0}, {"Software", 1}}, 0x304);
  x += RegisterEnumeration("TriggerActivation", {{"RisingEdge", 0}}, 0x308);
  x += Commands("TriggerSoftwareReg", 0x30C, {{"TriggerSoftware", 1}});
  x += Node("Float", "ExposureTime",
            Element("pValue", "ExposureTimeConverter") + Element("Min", "1") +
                Element("Max", "1000000") + Element("Unit", "us"));
  x += Node("Converter", "ExposureTimeConverter",
            Element("FormulaTo", "FROM") + Element("FormulaFrom", "TO") +
                Element("pValue", "ExposureTimeReg"),
            "Custom");
  x += IntReg("ExposureTimeReg", {kExposureUs}, "Custom");

  x +=
      Category("Scan3dControl", {"Scan3dDistanceUnit", "Scan3dCoordinateSystem", "Scan3dOutputMode",
                                 "Scan3dCoordinateSelector", "Scan3dCoordinateScale",
                                 "Scan3dCoordinateOffset", "Scan3dAxisMin", "Scan3dAxisMax",
                                 "Scan3dInvalidDataFlag", "Scan3dInvalidDataValue"});
  x += FixedEnumeration("Scan3dDistanceUnit", "Millimeter", 0);
  x += FixedEnumeration("Scan3dCoordinateSystem", "Cartesian", 0);
  x += FixedEnumeration("Scan3dOutputMode", "RectifiedC", 7);
  x += RegisterEnumeration("Scan3dCoordinateSelector", {{"CoordinateA", kA}, {"CoordinateC", kC}},
                           0xA000);
  x += FloatReg("Scan3dCoordinateScale", kCoordinateScale, coordinate, "Standard");
  x += FloatReg("Scan3dCoordinateOffset", kCoordinateOffset, coordinate, "Standard");
  x += FloatReg("Scan3dAxisMin", kAxisMin, coordinate, "Standard");
  x += FloatReg("Scan3dAxisMax", kAxisMax, coordinate, "Standard");
  x += RegisterBoolean("Scan3dInvalidDataFlag",
                       {.address = kInvalidFlag, .access = "RO", .index = coordinate});
  x += FloatReg("Scan3dInvalidDataValue", kInvalidValue, coordinate, "Standard");

  // Chunk features as SFNC names them. The fake camera cannot send chunk data, so the values
  // are device registers holding what was latched with the last profile.
  x += Category("ChunkDataControl", {"ChunkModeActive", "ChunkSelector", "ChunkEnable",
                                     "ChunkEncoderValue", "ChunkFrameID"});
  x += RegisterBoolean("ChunkModeActive", {0xA0C0});
  x += RegisterEnumeration("ChunkSelector", {{"EncoderValue", 0}, {"FrameID", 1}}, 0xA0C4);
  x += RegisterBoolean("ChunkEnable", {.address = 0xA0C8, .index = "ChunkSelectorReg"});
  x += ChunkRegister("ChunkEncoderValue", kChunkEncoderValue, "Signed");
  x += ChunkRegister("ChunkFrameID", kChunkFrameId, "Unsigned");

  x += Category("TransportLayerControl", {"PayloadSize"});
  return x + kXmlTail;
}

void WriteString(ArvFakeCamera* camera, guint32 address, size_t size, const std::string& s) {
  std::string padded = s.substr(0, size - 1);
  padded.resize(size, '\0');
  arv_fake_camera_write_memory(camera, address, size, padded.data());
}

void WriteU32(ArvFakeCamera* camera, guint32 address, guint32 v) {
  arv_fake_camera_write_register(camera, address, v);
}

// GenICam registers here are big-endian, as the XML declares.
void WriteU64(ArvFakeCamera* camera, guint32 address, uint64_t v) {
  unsigned char b[8];
  for (int i = 0; i < 8; ++i) b[i] = static_cast<unsigned char>(v >> (8 * (7 - i)));
  arv_fake_camera_write_memory(camera, address, sizeof b, b);
}

void WriteF64(ArvFakeCamera* camera, guint32 address, double v) {
  uint64_t bits = 0;
  std::memcpy(&bits, &v, sizeof bits);
  WriteU64(camera, address, bits);
}

}  // namespace

struct SimulatedGigEProfiler::Impl {
  std::shared_ptr<Profiler> source;
  ProfilerInfo info;
  std::string address;
  ArvGvFakeCamera* fake = nullptr;
  ArvFakeCamera* camera = nullptr;  // the fake's
  double z_scale_mm = 0.0;
  double z_offset_mm = 0.0;
  std::atomic<double> lost_ratio{0.0};
  std::atomic<int> sent{0};
  // The fake camera's thread only.
  guint32 applied_exposure_us = 0;
  bool dropping = false;

  // Runs on the fake camera's thread (which also answers GVCP) after a trigger, before the frame
  // is sent; the frame id of `buffer` is the one the frame will carry.
  static void Fill(ArvBuffer* buffer, void* data, guint32 exposure_us, guint32 /*gain*/,
                   ArvPixelFormat format) {
    auto* self = static_cast<Impl*>(data);
    if (self->dropping) {
      self->dropping = false;
      g_object_set(self->fake, "gvsp-lost-ratio", self->lost_ratio.load(), nullptr);
    }
    auto* out = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    const int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
    const bool c16 = format == ARV_PIXEL_FORMAT_COORD3D_C_16;
    if (out == nullptr) return;
    if ((!c16 && format != ARV_PIXEL_FORMAT_COORD3D_C_32F) || w != self->info.points || h != 1) {
      self->Drop("a " + std::to_string(w) + " x " + std::to_string(h) + " frame of format " +
                 std::to_string(static_cast<unsigned>(format)) + " is not a profile of " +
                 std::to_string(self->info.points) + " Coord3D_C16 or Coord3D_C32f points");
      return;
    }
    Status s = Status::Ok();
    if (exposure_us != self->applied_exposure_us) {
      s = self->source->SetExposure(static_cast<double>(exposure_us));
      if (s.ok()) self->applied_exposure_us = exposure_us;
    }
    Result<RangeProfile> profile = s.ok() ? self->source->Grab() : Result<RangeProfile>(s);
    if (!profile.ok()) {
      self->Drop(profile.status().ToString());
      return;
    }
    if (static_cast<int>(profile->z_mm.size()) != w) {
      self->Drop("the source sent " + std::to_string(profile->z_mm.size()) + " points");
      return;
    }
    // Ranges are clamped to the measuring range, as a sensor's output is, then quantised to the
    // nearest count; NaN is the invalid value. Pixel data is little-endian (PFNC).
    const double lo = self->info.z_min_mm, hi = self->info.z_max_mm;
    for (int i = 0; i < w; ++i) {
      const float z = profile->z_mm[i];
      const double v =
          (std::clamp(static_cast<double>(z), lo, hi) - self->z_offset_mm) / self->z_scale_mm;
      if (c16) {
        const guint32 raw =
            std::isnan(z)
                ? kInvalidCount
                : static_cast<guint32>(std::clamp(std::lround(v), 0L, long{kInvalidCount - 1}));
        out[2 * i] = static_cast<uint8_t>(raw & 0xFF);
        out[2 * i + 1] = static_cast<uint8_t>(raw >> 8);
      } else {
        const float raw = std::isnan(z) ? static_cast<float>(kInvalidCount) : static_cast<float>(v);
        uint32_t bits = 0;
        std::memcpy(&bits, &raw, sizeof bits);
        for (int b = 0; b < 4; ++b) out[4 * i + b] = static_cast<uint8_t>(bits >> (8 * b));
      }
    }
    WriteU64(self->camera, kChunkEncoderValue, static_cast<uint64_t>(profile->encoder));
    WriteU64(self->camera, kChunkFrameId, arv_buffer_get_frame_id(buffer));
    ++self->sent;
  }

  // The frame about to go out is lost on purpose: a sensor that could not make the profile sends
  // none.
  void Drop(const std::string& why) {
    Logger("sim")->error("simulated GigE profiler at {}: {}: profile not sent", address, why);
    dropping = true;
    g_object_set(fake, "gvsp-lost-ratio", 1.0, nullptr);
  }
};

SimulatedGigEProfiler::SimulatedGigEProfiler(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

SimulatedGigEProfiler::~SimulatedGigEProfiler() {
  if (impl_->fake != nullptr) g_object_unref(impl_->fake);  // joins its thread
}

Result<std::unique_ptr<SimulatedGigEProfiler>> SimulatedGigEProfiler::Start(
    std::shared_ptr<Profiler> source, const std::string& address, const std::string& serial) {
  if (source == nullptr) return InvalidArgument("the simulated GigE profiler needs a source");
  const ProfilerInfo info = source->info();
  if (info.points < 1 || info.points > kMaxPoints) {
    return InvalidArgument("the simulated GigE profiler serves 1.." + std::to_string(kMaxPoints) +
                           " points per profile, the source has " + std::to_string(info.points));
  }
  if (!(info.x_spacing_mm > 0) || !std::isfinite(info.x_start_mm)) {
    return InvalidArgument("the source's point spacing must be > 0 and its X start finite");
  }
  if (!(info.z_max_mm > info.z_min_mm) || !std::isfinite(info.z_min_mm) ||
      !std::isfinite(info.z_max_mm)) {
    return InvalidArgument("the source's measuring range must be finite and not empty");
  }
  if (serial.empty() || serial.size() >= 16) {
    return InvalidArgument("the serial number must have 1..15 characters");
  }
  INSITU_RETURN_IF_ERROR(CheckGvcpPortFree(address, "profiler"));

  auto impl = std::make_unique<Impl>();
  impl->source = std::move(source);
  impl->info = info;
  impl->address = address;
  // One count is the source's resolution, or coarser when its range needs more than the 65535
  // counts below the invalid value.
  const double span = info.z_max_mm - info.z_min_mm;
  impl->z_scale_mm =
      std::max(info.z_resolution_mm > 0 ? info.z_resolution_mm : 0.0, span / (kInvalidCount - 1));
  impl->z_offset_mm = info.z_min_mm;

  // The XML goes to the fake camera as a file: a memfd, read once while the camera is made.
  const int fd = memfd_create("insitu-profiler.xml", MFD_CLOEXEC);
  if (fd < 0) {
    return Status(StatusCode::kDeviceError,
                  std::string("simulated GigE profiler: memfd: ") + std::strerror(errno));
  }
  const std::string xml = ProfilerXml();
  const bool written = write(fd, xml.data(), xml.size()) == static_cast<ssize_t>(xml.size());
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  impl->fake = written ? arv_gv_fake_camera_new_full(address.c_str(), serial.c_str(), path.c_str())
                       : nullptr;
  close(fd);
  if (impl->fake == nullptr || !arv_gv_fake_camera_is_running(impl->fake)) {
    if (impl->fake != nullptr) g_object_unref(impl->fake);
    impl->fake = nullptr;
    return Status(StatusCode::kDeviceError, "cannot serve a GigE Vision profiler on " + address +
                                                (written ? " (no such local address)" : ""));
  }
  ArvFakeCamera* c = arv_gv_fake_camera_get_fake_camera(impl->fake);
  impl->camera = c;

  WriteString(c, kManufacturerName, 32, "insitu");
  WriteString(c, kModelName, 32, info.model.empty() ? "Simulated profiler" : info.model);
  WriteString(c, kSerialNumber, 16, serial);
  WriteString(c, kUserDefinedName, 16, "");
  WriteU32(c, kSensorWidth, info.points);
  WriteU32(c, kSensorHeight, 1);
  WriteU32(c, kWidth, info.points);
  WriteU32(c, kHeight, 1);
  WriteU32(c, kPixelFormat, ARV_PIXEL_FORMAT_COORD3D_C_16);
  WriteU32(c, kComponentEnable, 1);
  guint32 exposure_us = 0;
  arv_fake_camera_read_register(c, kExposureUs, &exposure_us);
  impl->applied_exposure_us = exposure_us;  // the source is told when the client changes it

  const double x_last = info.x_start_mm + (info.points - 1) * info.x_spacing_mm;
  WriteF64(c, kCoordinateScale + 8 * kA, info.x_spacing_mm);
  WriteF64(c, kCoordinateOffset + 8 * kA, info.x_start_mm);
  WriteF64(c, kAxisMin + 8 * kA, info.x_start_mm);
  WriteF64(c, kAxisMax + 8 * kA, x_last);
  WriteU32(c, kInvalidFlag + 4 * kA, 0);
  WriteF64(c, kCoordinateScale + 8 * kC, impl->z_scale_mm);
  WriteF64(c, kCoordinateOffset + 8 * kC, impl->z_offset_mm);
  WriteF64(c, kAxisMin + 8 * kC, info.z_min_mm);
  WriteF64(c, kAxisMax + 8 * kC, info.z_max_mm);
  WriteU32(c, kInvalidFlag + 4 * kC, 1);
  WriteF64(c, kInvalidValue + 8 * kC, kInvalidCount);
  WriteF64(c, kFrameRateMax, info.max_rate_hz);

  // The fake camera looks for a software trigger once per period of this rate: 1 kHz keeps the
  // latency of a grab near 1 ms.
  arv_fake_camera_set_trigger_frequency(c, 1000.0);
  arv_fake_camera_set_fill_pattern(c, &Impl::Fill, impl.get());
  return std::unique_ptr<SimulatedGigEProfiler>(new SimulatedGigEProfiler(std::move(impl)));
}

void SimulatedGigEProfiler::SetLostPacketRatio(double ratio) {
  impl_->lost_ratio = ratio;
  g_object_set(impl_->fake, "gvsp-lost-ratio", ratio, nullptr);
}

const std::string& SimulatedGigEProfiler::address() const { return impl_->address; }

int SimulatedGigEProfiler::profiles_sent() const { return impl_->sent.load(); }

double SimulatedGigEProfiler::z_scale_mm() const { return impl_->z_scale_mm; }

}  // namespace insitu::hw::aravis
