// The RTC-style list model: building, units of 16- and 20-bit heads, the field correction on
// every point, and points outside the field or the focus range refused, never clipped.
#include "insitu/pattern/galvo_list.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

namespace insitu::pattern {
namespace {

std::vector<ListCommand> Square(double half, double z) {
  ListBuilder b;
  b.SetJumpSpeed(5000).SetMarkSpeed(1000).SetLaserDelays(100, 120).SetScannerDelays(100, 50, 20)
      .SetLaserPower(0.5).SetLaserFrequency(30);
  b.JumpAbs({-half, -half, z});
  b.MarkAbs({half, -half, z}).MarkAbs({half, half, z}).MarkAbs({-half, half, z});
  b.MarkAbs({-half, -half, z});
  auto list = b.Finish();
  EXPECT_TRUE(list.ok()) << list.status().ToString();
  return *list;
}

TEST(GalvoList, BuildsAndEndsTheList) {
  const auto list = Square(10, 1.5);
  ASSERT_EQ(list.size(), 12u);
  EXPECT_EQ(list.back().op, ListOp::kEndOfList);
  EXPECT_EQ(list[7].op, ListOp::kMarkAbs);
}

TEST(GalvoList, BadCommandsAreNamed) {
  {
    ListBuilder b;
    b.SetJumpSpeed(-1).JumpAbs({0, 0, 0});
    const auto r = b.Finish();
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("list command 0 (set_jump_speed)"), std::string::npos)
        << r.status().message();
  }
  {
    ListBuilder b;
    b.JumpAbs({0, 0, 0}).MarkAbs({1, 0, 0});  // no mark speed yet
    const auto r = b.Finish();
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("before any set_mark_speed"), std::string::npos);
  }
  {
    ListBuilder b;
    b.SetMarkSpeed(100).MarkAbs({NAN, 0, 0});
    EXPECT_FALSE(b.Finish().ok());
  }
  {
    ListBuilder b;
    b.SetLaserPower(1.5);
    EXPECT_FALSE(b.Finish().ok());
  }
  EXPECT_FALSE(ListBuilder().Finish().ok());  // empty
}

// Full scale +-(2^(bits-1) - 1) counts over +-field: 16 bit, 80 mm -> 409.59 counts/mm;
// 20 bit -> 6553.59 counts/mm. Rounding to the nearest count: error <= half a count.
TEST(GalvoList, UnitsOf16And20BitHeads) {
  const auto list = Square(10, 1.5);
  for (int bits : {16, 20}) {
    HeadFormat f;
    f.bits = bits;
    const auto e = Emit(list, f);
    ASSERT_TRUE(e.ok()) << e.status().ToString();
    const double cpm = ((1 << (bits - 1)) - 1) / 80.0;
    const EmittedCommand& jump = (*e)[6];
    EXPECT_EQ(jump.op, ListOp::kJumpAbs);
    EXPECT_NEAR(jump.x, -10 * cpm, 0.5);
    EXPECT_NEAR(jump.z, 1.5 * ((1 << (bits - 1)) - 1) / 15.0, 0.5);
    EXPECT_NEAR((*e)[0].a, 5000 * 1e-3 * cpm, 0.5);  // bits per ms
    EXPECT_EQ((*e)[2].a, 10);                         // 100 us in 10 us ticks
    EXPECT_EQ((*e)[2].b, 12);
    EXPECT_EQ((*e)[4].a, 32768);                      // half power, 16-bit DAC
    EXPECT_EQ((*e)[5].a, 30000);                      // Hz
  }
  HeadFormat bad;
  bad.bits = 18;
  EXPECT_FALSE(Emit(list, bad).ok());
}

TEST(GalvoList, FieldCorrectionAppliesToEveryPoint) {
  const auto list = Square(10, 0);
  HeadFormat f;
  // A pincushion-like correction: scale by (1 + k r^2).
  const FieldCorrection corr = [](const Eigen::Vector3d& p) {
    const double k = 1e-4;
    const double s = 1 + k * p.head<2>().squaredNorm();
    return Eigen::Vector3d(p.x() * s, p.y() * s, p.z());
  };
  const auto plain = Emit(list, f);
  const auto corrected = Emit(list, f, corr);
  ASSERT_TRUE(plain.ok() && corrected.ok());
  int moved = 0;
  for (size_t i = 0; i < list.size(); ++i) {
    if (list[i].op != ListOp::kJumpAbs && list[i].op != ListOp::kMarkAbs) continue;
    // r^2 = 200 mm^2 at the corners: 2% of 10 mm = 0.2 mm = ~82 counts.
    EXPECT_NEAR(std::abs((*corrected)[i].x - (*plain)[i].x), 0.2 * f.counts_per_mm(), 1.0);
    ++moved;
  }
  EXPECT_EQ(moved, 5);
}

TEST(GalvoList, PointsOutsideFieldOrFocusAreRefusedNotClipped) {
  HeadFormat f;
  f.field_half_size_mm = 50;
  f.focus_half_range_mm = 5;
  {
    const auto e = Emit(Square(60, 0), f);
    ASSERT_FALSE(e.ok());
    EXPECT_EQ(e.status().code(), StatusCode::kOutOfRange);
    EXPECT_NE(e.status().message().find("list command 6 (jump_abs_3d) to (-60.000, -60.000"),
              std::string::npos)
        << e.status().message();
    EXPECT_NE(e.status().message().find("leaves the field +-50.000 mm"), std::string::npos);
  }
  {
    const auto e = Emit(Square(10, 6), f);
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.status().message().find("focus range +-5.000 mm"), std::string::npos);
  }
  {
    // Inside before correction, outside after it: refused, and both points are named.
    const FieldCorrection push = [](const Eigen::Vector3d& p) {
      return Eigen::Vector3d(p.x() * 1.1, p.y(), p.z());
    };
    const auto e = Emit(Square(48, 0), f, push);
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.status().message().find("corrected (-52.800"), std::string::npos)
        << e.status().message();
  }
}

TEST(GalvoList, TextFormAndDuration) {
  const auto list = Square(10, 0);
  HeadFormat f;
  const auto e = Emit(list, f);
  ASSERT_TRUE(e.ok());
  const std::string text = FormatEmitted(*e, f);
  EXPECT_NE(text.find("# insitu galvo list: 16-bit head"), std::string::npos);
  EXPECT_NE(text.find("mark_abs_3d 4096 -4096 0"), std::string::npos) << text;
  EXPECT_NE(text.find("set_end_of_list"), std::string::npos);
  // Jump 14.1 mm at 5000 mm/s (2.8 ms) + 100 us; 4 marks of 20 mm at 1000 mm/s (80 ms) + 4 x
  // 50 us.
  EXPECT_NEAR(ListDuration(list), 0.0028284 + 0.0001 + 0.080 + 0.0002, 1e-6);
}

}  // namespace
}  // namespace insitu::pattern
