#include "hw/aravis/gige_common.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace insitu::hw::aravis {
namespace {

std::string Text(const char* s) { return s != nullptr ? s : ""; }

// The DeviceUserID of the device at `address`; empty when it has none or does not answer.
std::string UserId(const char* address) {
  GError* error = nullptr;
  ArvCamera* c = arv_camera_new(address, &error);
  if (c == nullptr) {
    g_clear_error(&error);
    return "";
  }
  std::string user;
  if (arv_camera_is_feature_available(c, "DeviceUserID", &error)) {
    user = Text(arv_camera_get_string(c, "DeviceUserID", &error));
  }
  g_clear_error(&error);
  g_object_unref(c);
  return user;
}

}  // namespace

std::string Take(GError** error) {
  std::string m = (*error != nullptr && (*error)->message != nullptr) ? (*error)->message : "?";
  g_clear_error(error);
  return m;
}

bool IsIpv4(const std::string& s) {
  in_addr ip{};
  return inet_pton(AF_INET, s.c_str(), &ip) == 1;
}

const char* StatusName(ArvBufferStatus s) {
  switch (s) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "complete";
    case ARV_BUFFER_STATUS_CLEARED:
      return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "timed out waiting for its packets (packets lost)";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "missing packets";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "payload size mismatch";
    case ARV_BUFFER_STATUS_FILLING:
      return "still filling";
    case ARV_BUFFER_STATUS_ABORTED:
      return "aborted";
    default:
      return "unknown status";
  }
}

Result<std::string> FindDevice(const std::string& device, const std::string& noun) {
  if (IsIpv4(device)) return device;
  arv_update_device_list();
  const unsigned n = arv_get_n_devices();
  std::vector<std::string> seen;
  std::vector<unsigned> gige;
  for (unsigned i = 0; i < n; ++i) {
    if (Text(arv_get_device_protocol(i)) != "GigEVision") continue;
    gige.push_back(i);
    const std::string id = Text(arv_get_device_id(i));
    const std::string serial = Text(arv_get_device_serial_nbr(i));
    const std::string address = Text(arv_get_device_address(i));
    seen.push_back(id + " (serial " + serial + ", " + address + ")");
    if (!device.empty() && (device == serial || device == id)) return address;
  }
  std::string list;
  for (const std::string& s : seen) list += (list.empty() ? "" : ", ") + s;
  if (device.empty()) {
    if (gige.size() == 1) return Text(arv_get_device_address(gige[0]));
    if (gige.empty()) return NotFound("no GigE Vision " + noun + " found");
    return InvalidArgument("several GigE Vision " + noun + "s (" + list +
                           "): name one by serial, user id or address");
  }
  // A user id is not in the discovery reply: ask each device.
  for (unsigned i : gige) {
    if (UserId(arv_get_device_address(i)) == device) return Text(arv_get_device_address(i));
  }
  return NotFound("no GigE Vision " + noun + " '" + device + "'" +
                  (list.empty() ? std::string(" (none found)") : " (found: " + list + ")"));
}

Status CheckGvcpPortFree(const std::string& address, const std::string& noun) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(3956);
  if (inet_pton(AF_INET, address.c_str(), &a.sin_addr) != 1) {
    return InvalidArgument("'" + address + "' is not an IPv4 address");
  }
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  const int rc = fd < 0 ? -1 : bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a);
  const int err = errno;
  if (fd >= 0) close(fd);
  if (rc != 0) {
    return DeviceError("cannot serve a GigE Vision " + noun + " on " + address +
                       ":3956: " + std::strerror(err) +
                       (err == EADDRINUSE ? " (another device serves that address)" : ""));
  }
  return Status::Ok();
}

Connection::~Connection() {
  Close();
  for (std::thread& t : releases_) t.join();
}

Status Connection::Open(const std::string& address, const std::string& noun) {
  GError* error = nullptr;
  camera_ = arv_camera_new(address.c_str(), &error);
  if (camera_ == nullptr) {
    return NotFound("GigE " + noun + " at " + address + " does not answer: " + Take(&error));
  }
  return Status::Ok();
}

Status Connection::SetAcquisition(const std::string& trigger, int packet_size,
                                  double* exposure_us) {
  GError* error = nullptr;
  const auto fail = [&](const std::string& what) {
    return DeviceError(what + ": " + Take(&error));
  };
  arv_camera_set_trigger(camera_, trigger == "software" ? "Software" : trigger.c_str(), &error);
  if (error != nullptr) return fail("trigger " + trigger);
  arv_camera_gv_set_packet_size(camera_, packet_size, &error);
  if (error != nullptr) return fail("packet size " + std::to_string(packet_size));
  if (*exposure_us > 0) {
    arv_camera_set_exposure_time(camera_, *exposure_us, &error);
  } else {
    *exposure_us = arv_camera_get_exposure_time(camera_, &error);
  }
  if (error != nullptr) return fail("ExposureTime");
  return Status::Ok();
}

Status Connection::StartStream(int buffers, int socket_buffer_bytes) {
  GError* error = nullptr;
  stream_ = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
  if (stream_ == nullptr) return DeviceError("stream: " + Take(&error));
  if (ARV_IS_GV_STREAM(stream_)) {
    g_object_set(stream_, "packet-resend", ARV_GV_STREAM_PACKET_RESEND_ALWAYS, "socket-buffer",
                 ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size", socket_buffer_bytes,
                 nullptr);
  }
  const guint payload = arv_camera_get_payload(camera_, &error);
  if (error != nullptr) return DeviceError("PayloadSize: " + Take(&error));
  for (int i = 0; i < buffers; ++i)
    arv_stream_push_buffer(stream_, arv_buffer_new(payload, nullptr));
  arv_camera_start_acquisition(camera_, &error);
  if (error != nullptr) return DeviceError("AcquisitionStart: " + Take(&error));
  return Status::Ok();
}

void Connection::StopStream() {
  if (stream_ == nullptr) return;
  GError* error = nullptr;
  if (camera_ != nullptr) arv_camera_stop_acquisition(camera_, &error);
  g_clear_error(&error);
  g_object_unref(stream_);
  stream_ = nullptr;
}

void Connection::Close(bool reachable) {
  if (!reachable) {
    ArvStream* stream = stream_;
    ArvCamera* camera = camera_;
    stream_ = nullptr;
    camera_ = nullptr;
    releases_.emplace_back([stream, camera] {
      if (stream != nullptr) g_object_unref(stream);
      if (camera != nullptr) g_object_unref(camera);
    });
    return;
  }
  StopStream();
  if (camera_ != nullptr) {
    g_object_unref(camera_);
    camera_ = nullptr;
  }
}

}  // namespace insitu::hw::aravis
