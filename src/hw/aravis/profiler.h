// GenICam 3D line profilers (SFNC Scan3dControl) over GigE Vision through Aravis 0.8, and any
// hw::Profiler served as one (Aravis's in-process fake camera with a profiler's register map),
// so the whole profiler path runs over real GVCP/GVSP packets on a loopback address.
// Private to src/hw (the backend's folder, machine.cc and its tests): aravis/arv.h stays in
// src/hw/aravis; the options a job sets are in insitu/hw/aravis_options.h.
//
// What is read from the sensor (docs/hardware.md, "Line profilers"): one profile is one line of
// the range image (ComponentSelector=Range, PixelFormat Coord3D_C16 or Coord3D_C32f, Height 1).
// For the selected Scan3dCoordinateSelector, a transmitted value v means v * Scan3dCoordinateScale
// + Scan3dCoordinateOffset in the sensor frame, in mm (Scan3dDistanceUnit); CoordinateC is the
// range z, CoordinateA the X of point i (Scan3dOutputMode RectifiedC: offset + i * scale). A
// value equal to Scan3dInvalidDataValue, where Scan3dInvalidDataFlag is set, is NaN. The encoder
// count is the chunk ChunkEncoderValue; the timestamp and the frame counter are the stream's.
#pragma once

#include <memory>
#include <string>

#include "insitu/core/status.h"
#include "insitu/hw/aravis_options.h"
#include "insitu/hw/profiler.h"

namespace insitu::hw::aravis {

// Opens the sensor: the range component alone, the pixel format, one profile per frame, the
// trigger, the encoder chunk (ChunkModeActive, ChunkSelector EncoderValue, ChunkEnable) and the
// packet size; reads its geometry (points = Width; X start and spacing, measuring range and
// resolution from the Scan3d features) and starts its stream. info() is in the sensor frame of
// hw/profiler.h, in mm.
// Errors: invalid_argument (bad options; several devices and no choice), not_found (no such
// device: lists the devices seen), device_error (it answered but is not a profiler this backend
// reads, or could not be set up: names the feature and what it said).
//
// Grab: device_error for no profile in time (the link or the sensor is then dropped and opened
// again on the next grab), an incomplete frame (packets lost: the profile is dropped, never
// returned partly), a payload of another format or size, an encoder count that cannot be read.
// The profile's sequence is the stream's frame counter, widened past the 16-bit wrap of GigE
// Vision 1.x block ids (a reconnect makes it jump).
Result<std::unique_ptr<Profiler>> OpenProfiler(const ProfilerOptions& options);

// A GigE Vision 3D profiler on `address` (a loopback address such as 127.0.0.1; one device per
// address) whose profiles come from `source`: on each software trigger it calls source->Grab()
// and sends the profile as one Coord3D_C16 line (or Coord3D_C32f, as the client chose), at the
// exposure the client set over GVCP (whole microseconds; the source is told only when it
// changes). Its register map (a GenICam XML built into the binary) holds the source's geometry:
// Width = points, Height 1; CoordinateA scale/offset = the point spacing and X of point 0;
// CoordinateC scale = the source's z_resolution_mm (coarser when its range does not fit 65535
// counts), offset = z_min_mm, so a range is quantised to the nearest count; 65535 (and 65535.0
// in C32f) is the invalid value, sent for NaN; AcquisitionFrameRate's maximum is its
// max_rate_hz; DeviceModelName its model.
//
// The encoder count: Aravis 0.8's fake camera cannot send chunk data (its GVSP leader always
// says "image", so the receiver never sees chunks), so ChunkEncoderValue and ChunkFrameID are
// served as device registers holding what was latched with the last profile, which OpenProfiler
// reads over GVCP when a frame comes without chunk data (software trigger only). A profile the
// source cannot deliver (its Grab or SetExposure fails) is not sent: the client times out, as
// with a sensor that dropped the frame.
class SimulatedGigEProfiler {
 public:
  // Errors: invalid_argument (a source whose info() has no points, more than 16384, a spacing
  // <= 0 or an empty measuring range; a serial of 16 characters or more; not an IPv4 address),
  // device_error (the address cannot be served).
  static Result<std::unique_ptr<SimulatedGigEProfiler>> Start(std::shared_ptr<Profiler> source,
                                                              const std::string& address,
                                                              const std::string& serial);
  ~SimulatedGigEProfiler();
  // It owns the device on its address; a copy would serve it twice.
  SimulatedGigEProfiler(const SimulatedGigEProfiler&) = delete;
  SimulatedGigEProfiler& operator=(const SimulatedGigEProfiler&) = delete;

  // Drops GVSP packets with this probability (0..1): a lossy link.
  void SetLostPacketRatio(double ratio);
  const std::string& address() const;
  int profiles_sent() const;
  // The range of one count of Coord3D_C16 (Scan3dCoordinateScale of CoordinateC), mm.
  double z_scale_mm() const;

 private:
  struct Impl;
  explicit SimulatedGigEProfiler(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::hw::aravis
