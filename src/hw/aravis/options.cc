// CameraOptions and ProfilerOptions without Aravis: job files are checked where Aravis is not
// linked (fuzzing).
#include "insitu/hw/aravis_options.h"

namespace insitu::hw::aravis {
namespace {

// What a camera and a profiler take alike: the trigger, and the stream's packets, buffers,
// timeout and socket buffer.
Status ValidateTriggerAndStream(const std::string& trigger, int packet_size, int buffers,
                                double frame_timeout_ms, int socket_buffer_bytes) {
  if (trigger != "software" && trigger != "Line0" && trigger != "Line1" && trigger != "Line2" &&
      trigger != "Line3") {
    return InvalidArgument("trigger must be software or Line0..Line3");
  }
  if (packet_size < 576 || packet_size > 16000) {
    return InvalidArgument("packet_size must be in 576..16000 bytes");
  }
  if (buffers < 2 || buffers > 64) return InvalidArgument("buffers must be in 2..64");
  if (!(frame_timeout_ms > 0)) return InvalidArgument("frame_timeout_ms must be > 0");
  if (socket_buffer_bytes < 65536) return InvalidArgument("socket_buffer_bytes must be >= 65536");
  return Status::Ok();
}

}  // namespace

Status CameraOptions::Validate() const {
  if (bit_depth != 8 && bit_depth != 12 && bit_depth != 16) {
    return InvalidArgument("bit_depth must be 8 (Mono8), 12 (Mono12) or 16 (Mono16)");
  }
  INSITU_RETURN_IF_ERROR(ValidateTriggerAndStream(trigger, packet_size, buffers, frame_timeout_ms,
                                                  socket_buffer_bytes));
  if (roi_width < 0 || roi_height < 0) return InvalidArgument("roi sizes must be >= 0");
  return Status::Ok();
}

Status ProfilerOptions::Validate() const {
  if (pixel_format != "Coord3D_C16" && pixel_format != "Coord3D_C32f") {
    return InvalidArgument("pixel_format must be Coord3D_C16 or Coord3D_C32f");
  }
  return ValidateTriggerAndStream(trigger, packet_size, buffers, frame_timeout_ms,
                                  socket_buffer_bytes);
}

}  // namespace insitu::hw::aravis
