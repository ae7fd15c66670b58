// GigE Vision cameras through Aravis 0.8, and a GigE Vision camera served from the simulator
// (Aravis's in-process fake camera, every frame rendered by sim::SimWorld for the moment it is
// triggered), so the whole camera path runs over real GVCP/GVSP packets on a loopback address.
// Private to src/hw (the backend's folder, machine.cc and its tests): aravis/arv.h stays in
// src/hw/aravis; the options a job sets are in insitu/hw/aravis_options.h.
#pragma once

#include <memory>
#include <string>

#include "insitu/core/status.h"
#include "insitu/hw/aravis_options.h"
#include "insitu/hw/camera.h"

namespace insitu::sim {
class SimWorld;
}  // namespace insitu::sim

namespace insitu::hw::aravis {

// Opens the camera, sets software trigger, Mono8/Mono16 and the packet size, and starts its
// stream. Errors: not_found (no such camera: lists the cameras seen), invalid_argument (several
// cameras and no choice), device_error (it answered but could not be set up: names the feature).
Result<std::unique_ptr<Camera>> OpenCamera(const CameraOptions& options);

// A GigE Vision camera on `address` (a loopback address such as 127.0.0.1; one camera per
// address) whose frames the simulator renders: on each trigger, at the exposure, gain and
// binning the client set over GVCP. The sensor is the world's camera, which must fit the fake
// camera's 2048 x 2048.
class SimulatedGigECamera {
 public:
  // Errors: invalid_argument (a sensor over 2048 x 2048, a depth other than 8), device_error
  // (the address cannot be served).
  static Result<std::unique_ptr<SimulatedGigECamera>> Start(std::shared_ptr<sim::SimWorld> world,
                                                            const std::string& address,
                                                            const std::string& serial);
  ~SimulatedGigECamera();
  SimulatedGigECamera(const SimulatedGigECamera&) = delete;
  SimulatedGigECamera& operator=(const SimulatedGigECamera&) = delete;

  // Drops GVSP packets with this probability (0..1): a lossy link.
  void SetLostPacketRatio(double ratio);
  const std::string& address() const;
  int frames_rendered() const;

 private:
  struct Impl;
  explicit SimulatedGigECamera(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::hw::aravis
