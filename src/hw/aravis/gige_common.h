// What the Aravis camera backend (camera.cc), the line-profiler backend (profiler.cc) and the
// simulators that serve them (sim_gige.cc, sim_gige_profiler.cc) share: GError messages, finding
// a GigE Vision device by name, the buffer statuses, the link to an opened device, and the check
// that a local address can be served. Private to src/hw/aravis: arv.h stays here. `noun`, where
// a function takes one, names the kind of device in its messages ("camera", "profiler").
#pragma once

#include <arv.h>

#include <string>
#include <thread>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::hw::aravis {

// The message of a GError ("?" when there is none), which is cleared.
std::string Take(GError** error);

// `s` is a dotted-quad IPv4 address.
bool IsIpv4(const std::string& s);

// A buffer status as an error message says it ("missing packets").
const char* StatusName(ArvBufferStatus s);

// The address of the GigE Vision device `device` names: an IPv4 address (taken as it is, without
// asking), a serial number, a device id ("Vendor-Model-Serial") or a user id (DeviceUserID, asked
// of each device in turn); empty: the only GigE Vision device.
// Errors: not_found (nothing found, or nothing of that name: lists the devices seen, as "id
// (serial S, address)"), invalid_argument (several devices and `device` empty).
Result<std::string> FindDevice(const std::string& device, const std::string& noun);

// Aravis's fake camera reports running even when its GVCP port is taken (one device per
// address), so a simulator tries the port first: `address`'s UDP port 3956 is free.
// Errors: invalid_argument (not an IPv4 address), device_error (the port cannot be bound: why).
Status CheckGvcpPortFree(const std::string& address, const std::string& noun);

// An opened GigE Vision device (`camera`) and its stream. A device that stopped answering costs
// a GVCP timeout per command (5 tries x 500 ms in Aravis 0.8), so Close(false) sends none: it
// leaves only the control release Aravis makes when the camera object goes, and does that aside,
// since Aravis's teardown of such a device waits out its heartbeat too (about 10 s).
class Connection {
 public:
  Connection() = default;
  // Closes the device, then waits for the lost ones being released aside.
  ~Connection();
  // It holds the device's control channel; a copy would release it twice.
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // Opens the device at `address`; none may be open.
  // Errors: not_found ("GigE <noun> at <address> does not answer: ...").
  Status Open(const std::string& address, const std::string& noun);
  // Sets the trigger ("software", or the input line TriggerSource names), the GVSP packet size
  // and the exposure: `*exposure_us` where it is > 0, otherwise whatever the device was left at
  // is read into it (a grab's timeout includes it). Errors: device_error naming the setting
  // ("trigger Line1", "packet size 9000", "ExposureTime") and what the device said.
  Status SetAcquisition(const std::string& trigger, int packet_size, double* exposure_us);
  // A stream of `buffers` buffers of the device's payload, packets resent, in a socket buffer of
  // `socket_buffer_bytes`, and the acquisition started. Errors: device_error, naming the step
  // ("stream", "PayloadSize", "AcquisitionStart"); the stream made so far stays for Close.
  Status StartStream(int buffers, int socket_buffer_bytes);
  // Stops the acquisition and drops the stream (none: nothing to do).
  void StopStream();
  // `reachable`: the device still answers (its acquisition is stopped first); otherwise it is
  // released aside, as the class comment says.
  void Close(bool reachable = true);

  ArvCamera* camera() const { return camera_; }
  ArvStream* stream() const { return stream_; }

 private:
  ArvCamera* camera_ = nullptr;
  ArvStream* stream_ = nullptr;
  std::vector<std::thread> releases_;  // lost devices being released
};

}  // namespace insitu::hw::aravis
