#include "insitu/pattern/codes.h"

#include <memory>
#include <vector>

#include <dmtx.h>
#include <qrencode.h>

namespace insitu::pattern {

Result<Mask> QrCodeMask(const std::string& data, char level) {
  if (data.empty()) return InvalidArgument("QR code: no data to encode");
  QRecLevel l;
  switch (level) {
    case 'L': l = QR_ECLEVEL_L; break;
    case 'M': l = QR_ECLEVEL_M; break;
    case 'Q': l = QR_ECLEVEL_Q; break;
    case 'H': l = QR_ECLEVEL_H; break;
    default:
      return InvalidArgument(std::string("QR code: error correction must be L, M, Q or H, got '") +
                             level + "'");
  }
  std::unique_ptr<QRcode, void (*)(QRcode*)> code(
      QRcode_encodeString(data.c_str(), 0, l, QR_MODE_8, 1), QRcode_free);
  if (!code) {
    return InvalidArgument("QR code: cannot encode " + std::to_string(data.size()) +
                           " bytes at level " + level + " (too long for version 40?)");
  }
  Mask m;
  m.width = m.height = code->width;
  m.on.resize(static_cast<size_t>(m.width) * m.height);
  for (size_t i = 0; i < m.on.size(); ++i) m.on[i] = code->data[i] & 1;  // bit 0: dark module
  return m;
}

Result<Mask> DataMatrixMask(const std::string& data) {
  if (data.empty()) return InvalidArgument("Data Matrix: no data to encode");
  DmtxEncode* enc = dmtxEncodeCreate();
  if (enc == nullptr) return Internal("Data Matrix: encoder not created");
  dmtxEncodeSetProp(enc, DmtxPropModuleSize, 1);
  dmtxEncodeSetProp(enc, DmtxPropMarginSize, 0);
  std::vector<unsigned char> bytes(data.begin(), data.end());
  if (dmtxEncodeDataMatrix(enc, static_cast<int>(bytes.size()), bytes.data()) == DmtxFail) {
    dmtxEncodeDestroy(&enc);
    return InvalidArgument("Data Matrix: cannot encode " + std::to_string(data.size()) +
                           " bytes (too long for the largest symbol?)");
  }
  Mask m;
  m.width = enc->image->width;
  m.height = enc->image->height;
  m.on.resize(static_cast<size_t>(m.width) * m.height);
  for (int v = 0; v < m.height; ++v) {
    for (int u = 0; u < m.width; ++u) {
      int value = 255;
      // libdmtx images count rows from the bottom: row v of the mask is its height-1-v.
      dmtxImageGetPixelValue(enc->image, u, m.height - 1 - v, 0, &value);
      m.on[static_cast<size_t>(v) * m.width + u] = value < 128;
    }
  }
  dmtxEncodeDestroy(&enc);
  return m;
}

}  // namespace insitu::pattern
