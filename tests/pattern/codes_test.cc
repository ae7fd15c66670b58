// 2D codes: the masks decode back to their data with independent decoders (zbar for QR;
// libdmtx's decoder for Data Matrix; both find a mirrored or flipped symbol unreadable), and
// bad data is refused.
#include "insitu/pattern/codes.h"

#include <dmtx.h>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "support/zbar_qr.h"

namespace insitu::pattern {
namespace {

// The mask drawn as a camera would see a marked code: dark modules of `px` pixels on a light
// surface with a quiet zone of `quiet` modules.
cv::Mat Render(const Mask& m, int px, int quiet) {
  cv::Mat img((m.height + 2 * quiet) * px, (m.width + 2 * quiet) * px, CV_8UC1, cv::Scalar(255));
  for (int v = 0; v < m.height; ++v) {
    for (int u = 0; u < m.width; ++u) {
      if (m.at(u, v)) img(cv::Rect((u + quiet) * px, (v + quiet) * px, px, px)).setTo(0);
    }
  }
  return img;
}

using insitu::testing::DecodeQr;

TEST(Codes, QrMaskDecodes) {
  const std::string data = "insitu 2026-11-23 SN 0001";
  auto m = QrCodeMask(data, 'M');
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->width, m->height);
  EXPECT_EQ((m->width - 17) % 4, 0);  // QR sizes are 17 + 4 * version modules
  EXPECT_TRUE(m->at(0, 0) && m->at(6, 0) && m->at(0, 6));  // finder pattern corner
  EXPECT_EQ(DecodeQr(Render(*m, 4, 4)), data);
  EXPECT_FALSE(QrCodeMask("", 'M').ok());
  EXPECT_FALSE(QrCodeMask("x", 'Z').ok());
  EXPECT_FALSE(QrCodeMask(std::string(8000, 'a'), 'H').ok());
}

TEST(Codes, DataMatrixMaskDecodes) {
  const std::string data = "LOT 42 / insert 7";
  auto m = DataMatrixMask(data);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  // ECC 200: solid "L" finder on the left column and the bottom row.
  for (int v = 0; v < m->height; ++v) EXPECT_TRUE(m->at(0, v)) << v;
  for (int u = 0; u < m->width; ++u) EXPECT_TRUE(m->at(u, m->height - 1)) << u;
  cv::Mat img = Render(*m, 6, 2);
  DmtxImage* dimg = dmtxImageCreate(img.data, img.cols, img.rows, DmtxPack8bppK);
  ASSERT_NE(dimg, nullptr);
  dmtxImageSetProp(dimg, DmtxPropImageFlip, DmtxFlipNone);
  DmtxDecode* dec = dmtxDecodeCreate(dimg, 1);
  DmtxRegion* reg = dmtxRegionFindNext(dec, nullptr);
  std::string decoded;
  if (reg != nullptr) {
    DmtxMessage* msg = dmtxDecodeMatrixRegion(dec, reg, DmtxUndefined);
    if (msg != nullptr) {
      decoded.assign(reinterpret_cast<const char*>(msg->output), msg->outputIdx);
      dmtxMessageDestroy(&msg);
    }
    dmtxRegionDestroy(&reg);
  }
  dmtxDecodeDestroy(&dec);
  dmtxImageDestroy(&dimg);
  EXPECT_EQ(decoded, data);
  EXPECT_FALSE(DataMatrixMask("").ok());
}

}  // namespace
}  // namespace insitu::pattern
