// Numbers into a message: printf's format with up to three doubles (the job module's errors,
// warnings and plot titles). Internal to the job module.
#pragma once

#include <cstdio>
#include <string>

namespace insitu::job {

inline std::string Fmt(const char* format, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, format, a, b, c);
  return buf;
}

}  // namespace insitu::job
