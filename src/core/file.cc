#include "insitu/core/file.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace insitu {

Status WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    f.flush();
    if (!f.good()) {
      std::remove(tmp.c_str());
      return Status(StatusCode::kDeviceError, "cannot write " + tmp);
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    return Status(StatusCode::kDeviceError, "cannot write " + path + ": " + ec.message());
  }
  return Status::Ok();
}

}  // namespace insitu
