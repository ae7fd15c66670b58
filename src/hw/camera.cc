#include "insitu/hw/camera.h"

#include <string>

namespace insitu::hw {

Status CheckFrame(const Frame& frame, const CameraInfo& info) {
  const std::string which = "frame " + std::to_string(frame.sequence) + ": ";
  if (frame.bit_depth < 8 || frame.bit_depth > 16) {
    return Status(StatusCode::kDeviceError,
                  which + "bit depth " + std::to_string(frame.bit_depth) + " is not 8..16");
  }
  if (info.bit_depth != 0 && frame.bit_depth != info.bit_depth) {
    return Status(StatusCode::kDeviceError, which + std::to_string(frame.bit_depth) +
                                                "-bit samples from a camera set to " +
                                                std::to_string(info.bit_depth) + " bits");
  }
  if (frame.binning != 1 && frame.binning != 2 && frame.binning != 4) {
    return Status(StatusCode::kDeviceError,
                  which + "binning " + std::to_string(frame.binning) + " is not 1, 2 or 4");
  }
  const int max_w = info.sensor_width_px / frame.binning;
  const int max_h = info.sensor_height_px / frame.binning;
  if (frame.offset_x < 0 || frame.offset_y < 0 || frame.width <= 0 || frame.height <= 0 ||
      (info.sensor_width_px > 0 && frame.offset_x > max_w - frame.width) ||
      (info.sensor_height_px > 0 && frame.offset_y > max_h - frame.height)) {
    return Status(StatusCode::kDeviceError,
                  which + std::to_string(frame.width) + " x " + std::to_string(frame.height) +
                      " px at (" + std::to_string(frame.offset_x) + ", " +
                      std::to_string(frame.offset_y) + ") does not fit the " + std::to_string(max_w) + " x " +
                      std::to_string(max_h) + " px sensor at binning " +
                      std::to_string(frame.binning));
  }
  const size_t expected = frame.stride_bytes() * static_cast<size_t>(frame.height);
  if (frame.bytes.size() != expected) {
    return Status(StatusCode::kDeviceError,
                  which + "corrupt: its payload is " + std::to_string(frame.bytes.size()) +
                      " bytes, a " + std::to_string(frame.width) + " x " +
                      std::to_string(frame.height) + " px " + std::to_string(frame.bit_depth) +
                      "-bit frame is " + std::to_string(expected));
  }
  return Status::Ok();
}

Result<Frame> Camera::Grab() {
  INSITU_ASSIGN_OR_RETURN(Frame frame, GrabFrame());
  INSITU_RETURN_IF_ERROR(CheckFrame(frame, info()));
  return frame;
}

Status Camera::SetRegion(int first_row, int rows) {
  const int h = info().sensor_height_px;
  if (rows < 0 || first_row < 0 || (rows > 0 && first_row > h - rows)) {
    return OutOfRange("region: rows " + std::to_string(first_row) + ".." +
                      std::to_string(static_cast<long long>(first_row) + rows) +
                      " outside the sensor's 0.." + std::to_string(h));
  }
  return ApplyRegion(first_row, rows);
}

}  // namespace insitu::hw
