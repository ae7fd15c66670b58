#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "insitu/core/file.h"
#include "insitu/hw/lmc_cor.h"

namespace insitu::hw::lmc {
namespace {

constexpr int kNodes = 65;
constexpr size_t kLabelBytes = 22;
constexpr char kJczLabel[] = "JCZ_COR_2_1";
constexpr char kLmcLabel[] = "LMC1COR_1.0";
constexpr size_t kJczBytes = 33840;
constexpr size_t kJczTable = 0x24;
constexpr size_t kLmcHeaderDoubles = 63;
constexpr size_t kLmcScaleIndex = 43;
constexpr size_t kLmcTable = kLabelBytes + 2 + kLmcHeaderDoubles * 8;  // 0x210

template <typename T>
T Get(const std::string& b, size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof v);  // the files are little-endian, as this host
  return v;
}
template <typename T>
void Append(std::string* b, T v) {
  b->append(reinterpret_cast<const char*>(&v), sizeof v);
}

// The 22-byte label as EzCad writes it: 11 UTF-16LE characters.
std::string Label(const char* text) {
  std::string l;
  for (const char* c = text; *c != '\0'; ++c) {
    l.push_back(*c);
    l.push_back('\0');
  }
  l.resize(kLabelBytes, '\0');
  return l;
}

// The label's text, read as UTF-16LE (EzCad) or as 8-bit characters (other writers).
std::string LabelText(const std::string& b) {
  std::string wide, narrow;
  for (size_t i = 0; i + 1 < kLabelBytes; i += 2) {
    if (b[i] == '\0') break;
    wide.push_back(b[i]);
  }
  for (size_t i = 0; i < kLabelBytes && b[i] != '\0'; ++i) narrow.push_back(b[i]);
  return wide.size() > narrow.size() ? wide : narrow;
}

constexpr double kMaxOffset = 32767.0;  // what a WriteCorLine word can carry

}  // namespace

Eigen::Vector2d CorFile::NodeMm(int i, int j) const {
  return {(i * 1024.0 - 32768.0) / scale, (j * 1024.0 - 32768.0) / scale};
}

Result<CorFile> ReadCor(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return NotFound("cannot read the correction file " + path);
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string b = ss.str();
  const auto bad = [&](const std::string& what) { return ParseError(path + ": " + what); };
  if (b.size() < kLabelBytes) return bad("too short for a .cor file");
  CorFile cor;
  const std::string label = LabelText(b);
  size_t table = 0;
  if (label.rfind(kJczLabel, 0) == 0) {
    if (b.size() != kJczBytes) {
      return bad(std::to_string(b.size()) + " bytes; a JCZ_COR_2_1 file has " +
                 std::to_string(kJczBytes));
    }
    cor.format = CorFormat::kJcz2;
    cor.scale = Get<double>(b, 0x1C);
    table = kJczTable;
  } else if (label.rfind(kLmcLabel, 0) == 0) {
    const size_t need = kLmcTable + kNodes * kNodes * 16;
    if (b.size() < need) {
      return bad(std::to_string(b.size()) + " bytes; a LMC1COR_1.0 file needs " +
                 std::to_string(need));
    }
    cor.format = CorFormat::kLmc1;
    cor.scale = Get<double>(b, kLabelBytes + 2 + kLmcScaleIndex * 8);
    table = kLmcTable;
  } else {
    return bad("not a .cor file (label is neither JCZ_COR_2_1 nor LMC1COR_1.0)");
  }
  if (!std::isfinite(cor.scale) || !(cor.scale > 1.0 && cor.scale < 65536.0)) {
    return bad("scale " + std::to_string(cor.scale) + " units/mm is not a lens field");
  }
  cor.offsets.resize(kNodes * kNodes);
  for (size_t n = 0; n < cor.offsets.size(); ++n) {
    if (cor.format == CorFormat::kJcz2) {
      cor.offsets[n] = {static_cast<double>(Get<int32_t>(b, table + 8 * n)),
                        static_cast<double>(Get<int32_t>(b, table + 8 * n + 4))};
    } else {
      cor.offsets[n] = {Get<double>(b, table + 16 * n), Get<double>(b, table + 16 * n + 8)};
    }
    for (double v : cor.offsets[n]) {
      if (!std::isfinite(v) || std::abs(v) > kMaxOffset) {
        return bad("node " + std::to_string(n) + " holds an offset of " + std::to_string(v) +
                   " units, beyond the board's +-32767");
      }
    }
  }
  return cor;
}

Status WriteCor(const std::string& path, const CorFile& cor) {
  if (cor.offsets.size() != kNodes * kNodes) {
    return InvalidArgument("a .cor table has 65 x 65 nodes, not " +
                           std::to_string(cor.offsets.size()));
  }
  for (const auto& o : cor.offsets) {
    for (double v : o) {
      if (!std::isfinite(v) || std::abs(v) > kMaxOffset) {
        return OutOfRange("a .cor offset of " + std::to_string(v) +
                          " units is beyond the board's +-32767");
      }
    }
  }
  std::string b;
  if (cor.format == CorFormat::kJcz2) {
    b = Label(kJczLabel);
    b.append(6, '\0');
    Append(&b, cor.scale);
    for (const auto& o : cor.offsets) {
      for (double v : o) Append(&b, static_cast<int32_t>(std::lround(v)));
    }
    b.append(4, '\0');
  } else {
    b = Label(kLmcLabel);
    b.append(2, '\0');
    for (size_t k = 0; k < kLmcHeaderDoubles; ++k)
      Append(&b, k == kLmcScaleIndex ? cor.scale : 0.0);
    for (const auto& o : cor.offsets) {
      Append(&b, o[0]);
      Append(&b, o[1]);
    }
  }
  return WriteFileAtomically(path, b);
}

BoardCorrection ToBoard(const CorFile& cor) {
  BoardCorrection t;
  for (const auto& o : cor.offsets) {
    t.offsets.push_back(
        {static_cast<int32_t>(std::lround(o[0])), static_cast<int32_t>(std::lround(o[1]))});
  }
  return t;
}

std::string ToCorrectionCsv(const CorFile& cor) {
  std::string out =
      "# from a " + std::string(cor.format == CorFormat::kJcz2 ? kJczLabel : kLmcLabel) +
      " .cor file, lens " + std::to_string(cor.lens_mm()) + " mm\nx_mm,y_mm,dx_mm,dy_mm\n";
  char line[128];
  for (int i = 0; i < kNodes; ++i) {
    for (int j = 0; j < kNodes; ++j) {
      const Eigen::Vector2d p = cor.NodeMm(i, j);
      const auto& o = cor.offsets[i * kNodes + j];
      std::snprintf(line, sizeof line, "%.6f,%.6f,%.9f,%.9f\n", p.x(), p.y(), o[0] / cor.scale,
                    o[1] / cor.scale);
      out += line;
    }
  }
  return out;
}

CorFile FromCorrection(const std::function<Eigen::Vector2d(double, double)>& offset_mm,
                       double lens_mm, CorFormat format) {
  CorFile cor;
  cor.format = format;
  cor.scale = 65536.0 / lens_mm;
  cor.offsets.resize(kNodes * kNodes);
  for (int i = 0; i < kNodes; ++i) {
    for (int j = 0; j < kNodes; ++j) {
      const Eigen::Vector2d p = cor.NodeMm(i, j);
      const Eigen::Vector2d d = offset_mm(p.x(), p.y()) * cor.scale;
      cor.offsets[i * kNodes + j] = {d.x(), d.y()};
    }
  }
  return cor;
}

}  // namespace insitu::hw::lmc
