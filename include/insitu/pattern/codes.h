// 2D codes as raster masks, one mask pixel per module (seed 000 case 2 marks a QR code):
// QR through libqrencode, Data Matrix (ECC 200) through libdmtx. The quiet zone is not part of
// the mask: it is the unmarked part surface around the code. Hatch the mask with the module
// size as pixel_mm (raster.h).
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/pattern/raster.h"

namespace insitu::pattern {

// error_correction: one of L, M, Q, H. Errors: invalid_argument (empty data, bad level, data
// too long for any QR version).
Result<Mask> QrCodeMask(const std::string& data, char error_correction = 'M');

// Errors: invalid_argument (empty data, too long for any symbol size).
Result<Mask> DataMatrixMask(const std::string& data);

}  // namespace insitu::pattern
