// Any hw::Profiler served as a GenICam 3D line profiler: Aravis's fake GigE Vision camera with
// a profiler's register map (kProfilerXml below), each triggered frame filled with one profile
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
#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <string>

#include "insitu/core/log.h"
#include "insitu/hw/aravis_profiler.h"

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

// Ours, as kProfilerXml declares them. Per-coordinate registers are indexed by
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

// SFNC names and PFNC values (Coord3D_C16 0x011000B8 = 17825976, Coord3D_C32f 0x012000BF =
// 18874559). Chunk, Scan3d and component features follow SFNC 2.x; Scan3dOutputMode RectifiedC:
// the range of point i is at X = offset_A + i scale_A.
constexpr char kProfilerXml[] = R"XML(<?xml version="1.0" encoding="utf-8"?>
<RegisterDescription ModelName="InsituSimulatedProfiler" VendorName="insitu"
    StandardNameSpace="GEV" SchemaMajorVersion="1" SchemaMinorVersion="1" SchemaSubMinorVersion="0"
    MajorVersion="1" MinorVersion="0" SubMinorVersion="0" ToolTip="insitu simulated line profiler"
    ProductGuid="4F1B6C6E-2D55-4A55-9A37-6A6E10000001"
    VersionGuid="4F1B6C6E-2D55-4A55-9A37-6A6E10000002"
    xmlns="http://www.genicam.org/GenApi/Version_1_1"
    xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:schemaLocation="http://www.genicam.org/GenApi/Version_1_1 GenApiSchema_Version_1_1.xsd">

  <Category Name="Root" NameSpace="Standard">
    <pFeature>DeviceControl</pFeature>
    <pFeature>ImageFormatControl</pFeature>
    <pFeature>AcquisitionControl</pFeature>
    <pFeature>Scan3dControl</pFeature>
    <pFeature>ChunkDataControl</pFeature>
    <pFeature>TransportLayerControl</pFeature>
  </Category>

  <Category Name="DeviceControl" NameSpace="Standard">
    <pFeature>DeviceVendorName</pFeature>
    <pFeature>DeviceModelName</pFeature>
    <pFeature>DeviceSerialNumber</pFeature>
    <pFeature>DeviceUserID</pFeature>
  </Category>
  <StringReg Name="DeviceVendorName" NameSpace="Standard">
    <Address>0x48</Address><Length>32</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
  </StringReg>
  <StringReg Name="DeviceModelName" NameSpace="Standard">
    <Address>0x68</Address><Length>32</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
  </StringReg>
  <StringReg Name="DeviceSerialNumber" NameSpace="Standard">
    <Address>0xD8</Address><Length>16</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
  </StringReg>
  <StringReg Name="DeviceUserID" NameSpace="Standard">
    <Address>0xE8</Address><Length>16</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
  </StringReg>

  <Category Name="ImageFormatControl" NameSpace="Standard">
    <pFeature>ComponentSelector</pFeature>
    <pFeature>ComponentEnable</pFeature>
    <pFeature>SensorWidth</pFeature>
    <pFeature>SensorHeight</pFeature>
    <pFeature>Width</pFeature>
    <pFeature>Height</pFeature>
    <pFeature>OffsetX</pFeature>
    <pFeature>OffsetY</pFeature>
    <pFeature>PixelFormat</pFeature>
  </Category>
  <Enumeration Name="ComponentSelector" NameSpace="Standard">
    <EnumEntry Name="Range" NameSpace="Standard"><Value>4</Value></EnumEntry>
    <pValue>ComponentSelectorValue</pValue>
  </Enumeration>
  <Integer Name="ComponentSelectorValue" NameSpace="Custom"><Value>4</Value></Integer>
  <Boolean Name="ComponentEnable" NameSpace="Standard">
    <pValue>ComponentEnableReg</pValue><OnValue>1</OnValue><OffValue>0</OffValue>
  </Boolean>
  <IntReg Name="ComponentEnableReg" NameSpace="Custom">
    <Address>0xA0E8</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <IntReg Name="SensorWidth" NameSpace="Standard">
    <Address>0x11C</Address><Length>4</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <IntReg Name="SensorHeight" NameSpace="Standard">
    <Address>0x118</Address><Length>4</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <IntReg Name="Width" NameSpace="Standard">
    <Address>0x100</Address><Length>4</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Integer Name="Height" NameSpace="Standard">
    <pValue>HeightReg</pValue><Min>1</Min><Max>1</Max><Inc>1</Inc>
  </Integer>
  <IntReg Name="HeightReg" NameSpace="Custom">
    <Address>0x104</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Integer Name="OffsetX" NameSpace="Standard"><Value>0</Value><Min>0</Min><Max>0</Max></Integer>
  <Integer Name="OffsetY" NameSpace="Standard"><Value>0</Value><Min>0</Min><Max>0</Max></Integer>
  <Enumeration Name="PixelFormat" NameSpace="Standard">
    <EnumEntry Name="Coord3D_C16" NameSpace="Standard"><Value>17825976</Value></EnumEntry>
    <EnumEntry Name="Coord3D_C32f" NameSpace="Standard"><Value>18874559</Value></EnumEntry>
    <pValue>PixelFormatReg</pValue>
  </Enumeration>
  <IntReg Name="PixelFormatReg" NameSpace="Custom">
    <Address>0x128</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>

  <Category Name="AcquisitionControl" NameSpace="Standard">
    <pFeature>AcquisitionMode</pFeature>
    <pFeature>AcquisitionStart</pFeature>
    <pFeature>AcquisitionStop</pFeature>
    <pFeature>AcquisitionFrameRate</pFeature>
    <pFeature>TriggerSelector</pFeature>
    <pFeature>TriggerMode</pFeature>
    <pFeature>TriggerSource</pFeature>
    <pFeature>TriggerActivation</pFeature>
    <pFeature>TriggerSoftware</pFeature>
    <pFeature>ExposureTime</pFeature>
  </Category>
  <Enumeration Name="AcquisitionMode" NameSpace="Standard">
    <EnumEntry Name="Continuous" NameSpace="Standard"><Value>1</Value></EnumEntry>
    <pValue>AcquisitionModeReg</pValue>
  </Enumeration>
  <IntReg Name="AcquisitionModeReg" NameSpace="Custom">
    <Address>0x12C</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Command Name="AcquisitionStart" NameSpace="Standard">
    <pValue>AcquisitionReg</pValue><CommandValue>1</CommandValue>
  </Command>
  <Command Name="AcquisitionStop" NameSpace="Standard">
    <pValue>AcquisitionReg</pValue><CommandValue>0</CommandValue>
  </Command>
  <IntReg Name="AcquisitionReg" NameSpace="Custom">
    <Address>0x124</Address><Length>4</Length><AccessMode>WO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Float Name="AcquisitionFrameRate" NameSpace="Standard">
    <pValue>FrameRateMaxReg</pValue><Min>0</Min><pMax>FrameRateMaxReg</pMax><Unit>Hz</Unit>
  </Float>
  <FloatReg Name="FrameRateMaxReg" NameSpace="Custom">
    <Address>0xA0E0</Address><Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>
  <Enumeration Name="TriggerSelector" NameSpace="Standard">
    <EnumEntry Name="FrameStart" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <pValue>TriggerSelectorValue</pValue>
  </Enumeration>
  <Integer Name="TriggerSelectorValue" NameSpace="Custom"><Value>0</Value></Integer>
  <Enumeration Name="TriggerMode" NameSpace="Standard">
    <EnumEntry Name="Off" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <EnumEntry Name="On" NameSpace="Standard"><Value>1</Value></EnumEntry>
    <pValue>TriggerModeReg</pValue>
  </Enumeration>
  <IntReg Name="TriggerModeReg" NameSpace="Custom">
    <Address>0x300</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Enumeration Name="TriggerSource" NameSpace="Standard">
    <EnumEntry Name="Line0" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <EnumEntry Name="Software" NameSpace="Standard"><Value>1</Value></EnumEntry>
    <pValue>TriggerSourceReg</pValue>
  </Enumeration>
  <IntReg Name="TriggerSourceReg" NameSpace="Custom">
    <Address>0x304</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Enumeration Name="TriggerActivation" NameSpace="Standard">
    <EnumEntry Name="RisingEdge" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <pValue>TriggerActivationReg</pValue>
  </Enumeration>
  <IntReg Name="TriggerActivationReg" NameSpace="Custom">
    <Address>0x308</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Command Name="TriggerSoftware" NameSpace="Standard">
    <pValue>TriggerSoftwareReg</pValue><CommandValue>1</CommandValue>
  </Command>
  <IntReg Name="TriggerSoftwareReg" NameSpace="Custom">
    <Address>0x30C</Address><Length>4</Length><AccessMode>WO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Float Name="ExposureTime" NameSpace="Standard">
    <pValue>ExposureTimeConverter</pValue><Min>1</Min><Max>1000000</Max><Unit>us</Unit>
  </Float>
  <Converter Name="ExposureTimeConverter" NameSpace="Custom">
    <FormulaTo>FROM</FormulaTo><FormulaFrom>TO</FormulaFrom><pValue>ExposureTimeReg</pValue>
  </Converter>
  <IntReg Name="ExposureTimeReg" NameSpace="Custom">
    <Address>0x120</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>

  <Category Name="Scan3dControl" NameSpace="Standard">
    <pFeature>Scan3dDistanceUnit</pFeature>
    <pFeature>Scan3dCoordinateSystem</pFeature>
    <pFeature>Scan3dOutputMode</pFeature>
    <pFeature>Scan3dCoordinateSelector</pFeature>
    <pFeature>Scan3dCoordinateScale</pFeature>
    <pFeature>Scan3dCoordinateOffset</pFeature>
    <pFeature>Scan3dAxisMin</pFeature>
    <pFeature>Scan3dAxisMax</pFeature>
    <pFeature>Scan3dInvalidDataFlag</pFeature>
    <pFeature>Scan3dInvalidDataValue</pFeature>
  </Category>
  <Enumeration Name="Scan3dDistanceUnit" NameSpace="Standard">
    <EnumEntry Name="Millimeter" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <pValue>Scan3dDistanceUnitValue</pValue>
  </Enumeration>
  <Integer Name="Scan3dDistanceUnitValue" NameSpace="Custom"><Value>0</Value></Integer>
  <Enumeration Name="Scan3dCoordinateSystem" NameSpace="Standard">
    <EnumEntry Name="Cartesian" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <pValue>Scan3dCoordinateSystemValue</pValue>
  </Enumeration>
  <Integer Name="Scan3dCoordinateSystemValue" NameSpace="Custom"><Value>0</Value></Integer>
  <Enumeration Name="Scan3dOutputMode" NameSpace="Standard">
    <EnumEntry Name="RectifiedC" NameSpace="Standard"><Value>7</Value></EnumEntry>
    <pValue>Scan3dOutputModeValue</pValue>
  </Enumeration>
  <Integer Name="Scan3dOutputModeValue" NameSpace="Custom"><Value>7</Value></Integer>
  <Enumeration Name="Scan3dCoordinateSelector" NameSpace="Standard">
    <EnumEntry Name="CoordinateA" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <EnumEntry Name="CoordinateC" NameSpace="Standard"><Value>2</Value></EnumEntry>
    <pValue>Scan3dCoordinateSelectorReg</pValue>
  </Enumeration>
  <IntReg Name="Scan3dCoordinateSelectorReg" NameSpace="Custom">
    <Address>0xA000</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <FloatReg Name="Scan3dCoordinateScale" NameSpace="Standard">
    <Address>0xA010</Address><pIndex Offset="8">Scan3dCoordinateSelectorReg</pIndex>
    <Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>
  <FloatReg Name="Scan3dCoordinateOffset" NameSpace="Standard">
    <Address>0xA030</Address><pIndex Offset="8">Scan3dCoordinateSelectorReg</pIndex>
    <Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>
  <FloatReg Name="Scan3dAxisMin" NameSpace="Standard">
    <Address>0xA050</Address><pIndex Offset="8">Scan3dCoordinateSelectorReg</pIndex>
    <Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>
  <FloatReg Name="Scan3dAxisMax" NameSpace="Standard">
    <Address>0xA070</Address><pIndex Offset="8">Scan3dCoordinateSelectorReg</pIndex>
    <Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>
  <Boolean Name="Scan3dInvalidDataFlag" NameSpace="Standard">
    <pValue>Scan3dInvalidDataFlagReg</pValue><OnValue>1</OnValue><OffValue>0</OffValue>
  </Boolean>
  <IntReg Name="Scan3dInvalidDataFlagReg" NameSpace="Custom">
    <Address>0xA090</Address><pIndex Offset="4">Scan3dCoordinateSelectorReg</pIndex>
    <Length>4</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <FloatReg Name="Scan3dInvalidDataValue" NameSpace="Standard">
    <Address>0xA0A0</Address><pIndex Offset="8">Scan3dCoordinateSelectorReg</pIndex>
    <Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Endianess>BigEndian</Endianess>
  </FloatReg>

  <!-- Chunk features as SFNC names them. The fake camera cannot send chunk data, so the values
       are device registers holding what was latched with the last profile. -->
  <Category Name="ChunkDataControl" NameSpace="Standard">
    <pFeature>ChunkModeActive</pFeature>
    <pFeature>ChunkSelector</pFeature>
    <pFeature>ChunkEnable</pFeature>
    <pFeature>ChunkEncoderValue</pFeature>
    <pFeature>ChunkFrameID</pFeature>
  </Category>
  <Boolean Name="ChunkModeActive" NameSpace="Standard">
    <pValue>ChunkModeActiveReg</pValue><OnValue>1</OnValue><OffValue>0</OffValue>
  </Boolean>
  <IntReg Name="ChunkModeActiveReg" NameSpace="Custom">
    <Address>0xA0C0</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Enumeration Name="ChunkSelector" NameSpace="Standard">
    <EnumEntry Name="EncoderValue" NameSpace="Standard"><Value>0</Value></EnumEntry>
    <EnumEntry Name="FrameID" NameSpace="Standard"><Value>1</Value></EnumEntry>
    <pValue>ChunkSelectorReg</pValue>
  </Enumeration>
  <IntReg Name="ChunkSelectorReg" NameSpace="Custom">
    <Address>0xA0C4</Address><Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <Boolean Name="ChunkEnable" NameSpace="Standard">
    <pValue>ChunkEnableReg</pValue><OnValue>1</OnValue><OffValue>0</OffValue>
  </Boolean>
  <IntReg Name="ChunkEnableReg" NameSpace="Custom">
    <Address>0xA0C8</Address><pIndex Offset="4">ChunkSelectorReg</pIndex>
    <Length>4</Length><AccessMode>RW</AccessMode><pPort>Device</pPort>
    <Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <IntReg Name="ChunkEncoderValue" NameSpace="Standard">
    <Address>0xA0D0</Address><Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Cachable>NoCache</Cachable><Sign>Signed</Sign><Endianess>BigEndian</Endianess>
  </IntReg>
  <IntReg Name="ChunkFrameID" NameSpace="Standard">
    <Address>0xA0D8</Address><Length>8</Length><AccessMode>RO</AccessMode><pPort>Device</pPort>
    <Cachable>NoCache</Cachable><Sign>Unsigned</Sign><Endianess>BigEndian</Endianess>
  </IntReg>

  <Category Name="TransportLayerControl" NameSpace="Standard">
    <pFeature>PayloadSize</pFeature>
  </Category>
  <IntSwissKnife Name="PayloadSize" NameSpace="Standard">
    <pVariable Name="WIDTH">Width</pVariable>
    <pVariable Name="HEIGHT">Height</pVariable>
    <pVariable Name="PIXELFORMAT">PixelFormatReg</pVariable>
    <Formula>WIDTH * HEIGHT * ((PIXELFORMAT &gt;&gt; 16) &amp; 0xFF) / 8</Formula>
  </IntSwissKnife>

  <Port Name="Device" NameSpace="Standard"/>
</RegisterDescription>
)XML";

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

// The fake camera reports running even when its GVCP port is taken (one camera per address):
// try the port first.
Status CheckAddressFree(const std::string& address) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(3956);
  if (inet_pton(AF_INET, address.c_str(), &a.sin_addr) != 1) {
    return InvalidArgument("'" + address + "' is not an IPv4 address");
  }
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  const int rc = fd < 0 ? -1 : bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a);
  const int err = errno;
  if (fd >= 0) close(fd);
  if (rc != 0) {
    return Status(StatusCode::kDeviceError,
                  "cannot serve a GigE Vision profiler on " + address +
                      ":3956: " + std::strerror(err) +
                      (err == EADDRINUSE ? " (another device serves that address)" : ""));
  }
  return Status::Ok();
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
  INSITU_RETURN_IF_ERROR(CheckAddressFree(address));

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
  const size_t size = sizeof kProfilerXml - 1;
  const bool written = write(fd, kProfilerXml, size) == static_cast<ssize_t>(size);
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
