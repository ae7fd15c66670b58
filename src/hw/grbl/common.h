// What the GRBL stage and its options share: the serial rates it opens its port at (termios
// constants), the controller's axes, numbers as G-code and messages write them.
#pragma once

#include <termios.h>

#include <charconv>
#include <optional>
#include <string>
#include <string_view>

namespace insitu::hw::grbl {

// The axes of a GRBL controller, in the order of its status reports.
inline constexpr std::string_view kAxes = "XYZABC";

// The termios constant of `rate` baud; nothing for a rate the stage does not offer.
std::optional<speed_t> BaudConstant(int rate);

// Locale-independent fixed-point text: "-42.5000".
inline std::string Fixed(double v, int digits) {
  char b[64];
  const auto r = std::to_chars(b, b + sizeof b, v, std::chars_format::fixed, digits);
  return std::string(b, r.ptr);
}

}  // namespace insitu::hw::grbl
