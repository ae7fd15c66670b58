// What Options::Validate() methods share: one message form, "name must be <rule>, got <value>",
// starting with the field's name so the config layer can point at the line of that key.
#pragma once

#include <cmath>
#include <sstream>
#include <string>

#include "insitu/core/status.h"

namespace insitu {

template <typename T>
Status InvalidValue(const std::string& name, const std::string& rule, T value) {
  std::ostringstream os;
  os << name << " must be " << rule << ", got " << value;
  return InvalidArgument(os.str());
}

inline bool IsPositiveFinite(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace insitu
