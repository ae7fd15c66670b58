// The camera as the job layer sees it (simulator or GigE Vision through Aravis).
#pragma once

#include <string>

#include "insitu/core/frame.h"
#include "insitu/core/status.h"

namespace insitu::hw {

struct CameraInfo {
  std::string model;
  std::string serial;
  int sensor_width_px = 0;   // full sensor, unbinned
  int sensor_height_px = 0;
  int bit_depth = 8;
};

class Camera {
 public:
  Camera() = default;
  virtual ~Camera() = default;
  // A Camera owns a stream; copies would fight over it.
  Camera(const Camera&) = delete;
  Camera& operator=(const Camera&) = delete;

  virtual CameraInfo info() const = 0;
  // Errors: out_of_range with the allowed range.
  virtual Status SetExposure(double exposure_us) = 0;
  virtual Status SetGain(double gain_db) = 0;
  // Pixels of the sensor averaged into one, per axis (1, 2 or 4).
  virtual Status SetBinning(int binning) = 0;
  // The region of interest: `rows` rows of the full sensor from `first_row` (unbinned), all
  // columns; rows 0: the whole sensor. A camera may widen it to its own increments; each frame
  // says where it lies (Frame::offset_y). Fewer rows travel faster: a GigE camera's frame rate
  // rises as the region shrinks. Errors: out_of_range (outside the sensor), failed_precondition
  // (a camera without regions).
  virtual Status SetRegion(int first_row, int rows) {
    (void)first_row;
    return rows == 0 ? Status::Ok()
                     : FailedPrecondition("this camera cannot read a region of its sensor");
  }
  // Exposes once and returns the frame, checked: a frame whose payload does not match its
  // size and bit depth, or whose size is not the sensor's at the frame's binning, is an error
  // here and never reaches image code. Errors: device_error (timeout, lost packets, a corrupt
  // frame, naming what is wrong).
  Result<Frame> Grab();

 protected:
  // The backend's grab.
  virtual Result<Frame> GrabFrame() = 0;
};

// Why `frame` cannot be what a camera with `info` delivers, or OK. The check Grab makes.
Status CheckFrame(const Frame& frame, const CameraInfo& info);

}  // namespace insitu::hw
