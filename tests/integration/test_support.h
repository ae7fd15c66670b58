// Helpers shared by the integration tests: a calibration set that is exactly the simulated
// camera (what a perfect calibration would measure), for checking the reconstruction maths
// apart from calibration error. Tests may read the simulator's truth; the product never does.
#pragma once

#include "insitu/calib/calibration.h"
#include "insitu/job/scan.h"
#include "insitu/sim/camera_model.h"
#include "insitu/sim/world_options.h"

namespace insitu::testing {

// The step gauge's 20 lines 1 mm apart on binned 2x2 frames: the scan the default suite
// affords end to end.
inline job::ScanOptions FastScan() {
  job::ScanOptions o;
  o.x_start_mm = -9.5;
  o.x_end_mm = 9.5;
  o.line_spacing_mm = 1.0;
  o.binning = 2;
  return o;
}

inline calib::CalibrationSet PerfectCalibration(const sim::WorldOptions& world) {
  const sim::CameraModel cam(world.camera);
  calib::CalibrationSet set;
  set.produced_by = "test: simulator truth";
  set.camera.model = world.camera.model;
  set.camera.serial = world.camera.serial;
  set.camera.lens = world.camera.lens;
  set.camera.width_px = world.camera.width_px;
  set.camera.height_px = world.camera.height_px;
  set.camera.fx = cam.fx();
  set.camera.fy = cam.fy();
  set.camera.cx = cam.cx();
  set.camera.cy = cam.cy();
  set.camera.k1 = world.camera.k1;
  set.camera.k2 = world.camera.k2;
  set.camera.p1 = world.camera.p1;
  set.camera.p2 = world.camera.p2;
  set.camera.k3 = world.camera.k3;
  set.galvo.pivot_height_mm = world.scan_head.y_mirror_height_mm;
  set.galvo.camera_from_galvo = cam.camera_from_world();
  return set;
}

}  // namespace insitu::testing
