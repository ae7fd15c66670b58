// Reads a QR code back from an 8-bit grey image with zbar (Debian's OpenCV has no QR decoder):
// the independent check that a generated or marked code is right. Empty if none was found.
#pragma once

#include <string>

#include <opencv2/core.hpp>
#include <zbar.h>

namespace insitu::testing {

inline std::string DecodeQr(const cv::Mat& gray) {
  using namespace zbar;  // its C API, wrapped in a namespace when included from C++
  zbar_image_scanner_t* scanner = zbar_image_scanner_create();
  zbar_image_scanner_set_config(scanner, ZBAR_NONE, ZBAR_CFG_ENABLE, 1);
  zbar_image_t* image = zbar_image_create();
  zbar_image_set_format(image, zbar_fourcc('Y', '8', '0', '0'));
  zbar_image_set_size(image, gray.cols, gray.rows);
  zbar_image_set_data(image, gray.data, gray.total(), nullptr);
  std::string out;
  if (zbar_scan_image(scanner, image) > 0) {
    const zbar_symbol_t* symbol = zbar_image_first_symbol(image);
    if (zbar_symbol_get_type(symbol) == ZBAR_QRCODE) out = zbar_symbol_get_data(symbol);
  }
  zbar_image_destroy(image);
  zbar_image_scanner_destroy(scanner);
  return out;
}

}  // namespace insitu::testing
