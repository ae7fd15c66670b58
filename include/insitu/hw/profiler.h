// A 2D laser line profiler (a "3D profile sensor"): a laser fan and a camera at a triangulation
// angle give, per exposure, one profile: N points along the laser line (the sensor's X) at a fixed
// spacing, each a range (the sensor's Z) or the invalid value where the camera saw no line
// (occlusion at a steep flank, no signal, out of range). Each profile carries the encoder count
// the sensor latched with its exposure, so the position it was taken at travels with it.
//
// Sensor frame (SCS, seed 002 eq. 5): origin at the middle of the laser line at the reference
// distance, X along the line, Z toward the sensor (a higher surface reads a larger z), Y the
// laser plane's normal (the direction the sensor is carried across a part).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::hw {

struct ProfilerInfo {
  std::string model;
  std::string serial;
  int points = 0;              // per profile
  double x_start_mm = 0.0;     // X of point 0 in the sensor frame
  double x_spacing_mm = 0.0;   // between points along the line
  double z_min_mm = 0.0;       // measuring range in the sensor frame; equal when the sensor
  double z_max_mm = 0.0;       // does not state it (a float range output without axis limits)
  double z_resolution_mm = 0.0;  // one count of the range output
  double max_rate_hz = 0.0;      // profiles per second at the current exposure
};

// One profile: z_mm[i] at X = x_start_mm + i x_spacing_mm; NaN where the sensor sent its
// invalid value.
struct RangeProfile {
  double x_start_mm = 0.0;
  double x_spacing_mm = 0.0;
  std::vector<float> z_mm;
  int64_t encoder = 0;      // the encoder count latched with the exposure
  uint64_t sequence = 0;    // the sensor's frame counter
  double timestamp_s = 0.0; // the sensor's clock at the exposure

  int valid_points() const;
};

class Profiler {
 public:
  Profiler() = default;
  virtual ~Profiler() = default;
  // A Profiler owns a stream; copies would fight over it.
  Profiler(const Profiler&) = delete;
  Profiler& operator=(const Profiler&) = delete;

  virtual ProfilerInfo info() const = 0;
  // Errors: out_of_range with the allowed range.
  virtual Status SetExposure(double exposure_us) = 0;
  // Exposes once (software trigger) and returns the profile, checked: a profile whose point
  // count or spacing is not the sensor's, or with a valid range outside its measuring range, is
  // an error here. Errors: device_error (no profile in time, a corrupt payload, the link lost:
  // naming what is wrong).
  Result<RangeProfile> Grab();

 protected:
  virtual Result<RangeProfile> GrabProfile() = 0;
};

// Why `profile` cannot be what a sensor with `info` delivers, or OK. The check Grab makes.
Status CheckProfile(const RangeProfile& profile, const ProfilerInfo& info);

}  // namespace insitu::hw
