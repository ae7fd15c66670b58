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
  // rises as the region shrinks. Errors: out_of_range (outside the sensor: checked here, once
  // for every backend), failed_precondition (a camera without regions).
  Status SetRegion(int first_row, int rows);

  // The trigger input wired to the scan head's trigger output, if any: then a scan exposes
  // each line on the head's pulse (Scanner::RunTriggeredSweep) instead of a grab. Single grabs
  // (calibration, verification) still trigger in software.
  virtual bool head_triggered() const { return false; }
  // From here on Grab returns the frames the head's pulses expose, in the order of the
  // pulses, none dropped and none from before; Grab waits for the next one. Errors:
  // failed_precondition (no trigger input), device_error.
  virtual Status StartTriggered() {
    return FailedPrecondition("this camera has no trigger input wired to the scan head");
  }
  // Back to software trigger (also after a failed scan); frames of pulses that came after
  // the last grab are dropped.
  virtual Status StopTriggered() { return Status::Ok(); }
  // From another thread: the head's sweep has ended early (it failed), so no pulse will come:
  // a Grab waiting for a triggered frame returns now with device_error rather than at its
  // timeout. A camera that cannot be woken waits its timeout.
  virtual void WakeTriggered() {}
  // The highest frame rate the camera keeps at its exposure, binning and region (Hz): the
  // link and the readout; 0 if the camera does not tell. A triggered scan paces its lines
  // to it, since a pulse while the camera is busy is ignored.
  virtual double max_frame_rate_hz() const { return 0.0; }

  // Exposes once and returns the frame, checked: a frame whose payload does not match its
  // size and bit depth, or whose size is not the sensor's at the frame's binning, is an error
  // here and never reaches image code. Errors: device_error (timeout, lost packets, a corrupt
  // frame, naming what is wrong).
  Result<Frame> Grab();

 protected:
  // The backend's grab.
  virtual Result<Frame> GrabFrame() = 0;
  // The backend's region: the rows lie on the sensor (SetRegion checked them).
  virtual Status ApplyRegion(int first_row, int rows) {
    (void)first_row;
    return rows == 0 ? Status::Ok()
                     : FailedPrecondition("this camera cannot read a region of its sensor");
  }
};

// Why `frame` cannot be what a camera with `info` delivers, or OK. The check Grab makes.
Status CheckFrame(const Frame& frame, const CameraInfo& info);

}  // namespace insitu::hw
