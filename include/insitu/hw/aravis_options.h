// What a job's `machine:` section sets for the Aravis backend: a GigE Vision camera
// (camera: aravis, its `aravis:` part) and a GenICam 3D line profiler (profiler: aravis, its
// `aravis_profiler:` part). The devices themselves stay in src/hw/aravis (camera.h,
// profiler.h), with aravis/arv.h.
#pragma once

#include <string>

#include "insitu/core/status.h"

namespace insitu::hw::aravis {

struct CameraOptions {
  // Which camera: an IP address, a serial number, a device id ("Vendor-Model-Serial") or a
  // user id (DeviceUserID). Empty: the only GigE camera found.
  std::string device;
  int bit_depth = 8;  // 8 (Mono8), 12 (Mono12, in 16-bit samples) or 16 (Mono16)
  // "software": each grab triggers the frame. "Line0".."Line3": that input is wired to the
  // scan head's trigger output (lmc.trigger_port): a scan's frames are exposed by the head's
  // pulses, one per line, and each grab waits for the next one up to the timeout; single
  // grabs (calibration, verification) still trigger in software.
  std::string trigger = "software";
  // The image read out, unbinned, from the sensor's corner (0: the whole sensor). It is what
  // info() reports as the sensor and what the calibration file must describe.
  int roi_width = 0;
  int roi_height = 0;
  int packet_size = 8192;  // bytes; jumbo frames need the link's MTU (docs/hardware.md)
  int buffers = 4;
  double frame_timeout_ms = 1000.0;   // beyond the exposure
  int socket_buffer_bytes = 4 << 20;  // capped by net.core.rmem_max for non-root users
  bool reconnect = true;              // a camera that went away is opened again on the next grab

  Status Validate() const;
};

struct ProfilerOptions {
  // Which sensor: an IP address, a serial number, a device id ("Vendor-Model-Serial") or a
  // user id (DeviceUserID). Empty: the only GigE Vision device found.
  std::string device;
  // "Coord3D_C16" (16-bit unsigned counts) or "Coord3D_C32f" (32-bit float).
  std::string pixel_format = "Coord3D_C16";
  // "software": each grab triggers the profile; "Line0".."Line3": a hardware trigger on that
  // input (the grab waits for the pulse and the profile, up to the timeout).
  std::string trigger = "software";
  int packet_size = 8192;  // bytes; jumbo frames need the link's MTU (docs/hardware.md)
  int buffers = 4;
  double frame_timeout_ms = 1000.0;   // beyond the exposure
  int socket_buffer_bytes = 4 << 20;  // capped by net.core.rmem_max for non-root users
  bool reconnect = true;              // a sensor that went away is opened again on the next grab

  Status Validate() const;
};

}  // namespace insitu::hw::aravis
