// The LMC board over libusb: interface 0, bulk OUT 0x02, bulk IN 0x88, short timeouts with
// retries. Every failure names the board (bus-address VID:PID) and what libusb said.
#include <libusb.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "hw/lmc/lmc.h"
#include "insitu/core/log.h"

namespace insitu::hw::lmc {
namespace {

constexpr unsigned char kOut = 0x02;
constexpr unsigned char kIn = 0x88;

std::string Hex4(uint16_t v) {
  char b[8];
  std::snprintf(b, sizeof b, "%04x", v);
  return b;
}

class UsbTransport : public Transport {
 public:
  UsbTransport(libusb_context* context, libusb_device_handle* handle, std::string name,
               const UsbSelector& selector)
      : context_(context), handle_(handle), name_(std::move(name)), selector_(selector) {}

  ~UsbTransport() override {
    libusb_release_interface(handle_, 0);
    libusb_close(handle_);
    libusb_exit(context_);
  }

  Status Write(const uint8_t* data, size_t size) override {
    if (stale_reply_) Drain();
    return Transfer(kOut, const_cast<uint8_t*>(data), size, "write");
  }
  Status Read(uint8_t* data, size_t size) override {
    const Status s = Transfer(kIn, data, size, "read");
    // A reply that comes after we gave up would answer the next command: drop it first.
    if (!s.ok()) stale_reply_ = true;
    return s;
  }
  std::string Describe() const override { return name_; }

 private:
  // A timed-out transfer may have moved part of the data: the retry goes on from there, never
  // sends bytes twice (a list shifted by a few bytes would be executed as garbage).
  Status Transfer(unsigned char endpoint, uint8_t* data, size_t size, const char* what) {
    size_t moved = 0;
    int rc = LIBUSB_ERROR_TIMEOUT;
    for (int attempt = 0; attempt <= selector_.retries && rc == LIBUSB_ERROR_TIMEOUT; ++attempt) {
      int done = 0;
      rc = libusb_bulk_transfer(handle_, endpoint, data + moved, static_cast<int>(size - moved),
                                &done, static_cast<unsigned>(selector_.timeout_ms));
      moved += static_cast<size_t>(std::max(done, 0));
      if (rc == LIBUSB_ERROR_TIMEOUT && moved == size) rc = 0;
      if (rc == LIBUSB_ERROR_TIMEOUT && attempt < selector_.retries) {
        Logger("hw")->warn("{}: {} of {} bytes timed out after {}, retrying", name_, what, size,
                           moved);
      }
    }
    const int done = static_cast<int>(moved);
    if (rc != 0) {
      return Status(
          StatusCode::kDeviceError,
          name_ + ": " + what + " of " + std::to_string(size) +
              " bytes failed: " + libusb_error_name(rc) +
              (rc == LIBUSB_ERROR_NO_DEVICE ? " (the board was unplugged or lost power)" : ""));
    }
    if (static_cast<size_t>(done) != size) {
      return Status(StatusCode::kDeviceError, name_ + ": " + what + " moved " +
                                                  std::to_string(done) + " of " +
                                                  std::to_string(size) + " bytes");
    }
    return Status::Ok();
  }

  // Reads whatever replies are pending, with a short timeout, and drops them.
  void Drain() {
    uint8_t junk[64];
    int done = 0;
    for (int k = 0; k < 16; ++k) {
      if (libusb_bulk_transfer(handle_, kIn, junk, sizeof junk, &done, 10) != 0) break;
    }
    stale_reply_ = false;
  }

  bool stale_reply_ = false;
  libusb_context* context_;
  libusb_device_handle* handle_;
  std::string name_;
  UsbSelector selector_;
};

}  // namespace

Result<std::unique_ptr<Transport>> OpenUsb(const UsbSelector& s) {
  INSITU_RETURN_IF_ERROR(s.Validate());
  libusb_context* context = nullptr;
  if (const int rc = libusb_init(&context); rc != 0) {
    return Status(StatusCode::kDeviceError,
                  std::string("libusb cannot start: ") + libusb_error_name(rc));
  }
  libusb_device** devices = nullptr;
  const ssize_t n = libusb_get_device_list(context, &devices);
  if (n < 0) {
    libusb_exit(context);
    return Status(StatusCode::kDeviceError, std::string("libusb cannot list the USB devices: ") +
                                                libusb_error_name(static_cast<int>(n)));
  }
  const std::string wanted = Hex4(s.vid) + ":" + Hex4(s.pid);
  std::string seen;
  libusb_device* chosen = nullptr;
  for (ssize_t i = 0; i < n; ++i) {
    libusb_device_descriptor d{};
    if (libusb_get_device_descriptor(devices[i], &d) != 0) continue;
    if (d.idVendor != s.vid || d.idProduct != s.pid) continue;
    const int bus = libusb_get_bus_number(devices[i]);
    const int address = libusb_get_device_address(devices[i]);
    seen += (seen.empty() ? "" : ", ") + std::to_string(bus) + "-" + std::to_string(address);
    if ((s.bus < 0 || s.bus == bus) && (s.address < 0 || s.address == address) && !chosen) {
      chosen = devices[i];
    }
  }
  const auto fail = [&](StatusCode code, const std::string& message) {
    if (devices != nullptr) libusb_free_device_list(devices, 1);
    libusb_exit(context);
    return Status(code, message);
  };
  if (chosen == nullptr) {
    return fail(StatusCode::kNotFound,
                "no LMC board " + wanted +
                    (s.bus >= 0 ? " at bus " + std::to_string(s.bus) : std::string()) +
                    (s.address >= 0 ? " address " + std::to_string(s.address) : std::string()) +
                    (seen.empty() ? " on any USB bus" : " (boards with that id: " + seen + ")"));
  }
  const std::string name = "LMC usb " + std::to_string(libusb_get_bus_number(chosen)) + "-" +
                           std::to_string(libusb_get_device_address(chosen)) + " " + wanted;
  libusb_device_handle* handle = nullptr;
  if (const int rc = libusb_open(chosen, &handle); rc != 0) {
    return fail(
        StatusCode::kDeviceError,
        name + ": cannot open: " + libusb_error_name(rc) +
            (rc == LIBUSB_ERROR_ACCESS ? " (install the udev rule in docs/hardware.md)" : ""));
  }
  libusb_free_device_list(devices, 1);
  devices = nullptr;
  libusb_set_auto_detach_kernel_driver(handle, 1);
  if (const int rc = libusb_claim_interface(handle, 0); rc != 0) {
    libusb_close(handle);
    return fail(StatusCode::kDeviceError,
                name + ": cannot claim interface 0: " + libusb_error_name(rc) +
                    (rc == LIBUSB_ERROR_BUSY ? " (another program holds the board)" : ""));
  }
  return std::unique_ptr<Transport>(std::make_unique<UsbTransport>(context, handle, name, s));
}

}  // namespace insitu::hw::lmc
