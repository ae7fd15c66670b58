// .cor files (lmc_cor.h): the bytes as stored, readings applied only where a table meets the
// galvo frame.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
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
constexpr size_t kJczScale = 0x1C;
constexpr size_t kJczTable = 0x24;
constexpr size_t kJczTrailer = 4;
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
constexpr char kReadingComment[] = "reading:";

// The entry in file order that holds node (i, j) (i along x) for a reading.
size_t Entry(int i, int j, const CorReading& reading) {
  return reading.y_major ? static_cast<size_t>(j) * kNodes + i
                         : static_cast<size_t>(i) * kNodes + j;
}

}  // namespace

std::string CorReading::Name() const {
  return std::string("pair ") + (pair_dy_dx ? "(dy, dx)" : "(dx, dy)") +
         (y_major ? ", y-major" : ", x-major") + ", signs (" + (negate_dx ? "-" : "+") + "," +
         (negate_dy ? "-" : "+") + ")";
}

std::string CorReading::Code() const {
  return std::string(pair_dy_dx ? "dy-dx" : "dx-dy") + (y_major ? ",y-major," : ",x-major,") +
         (negate_dx ? "-" : "+") + (negate_dy ? "-" : "+");
}

Result<CorReading> ParseCorReading(const std::string& code) {
  CorReading r;
  bool pair = false, order = false, signs = false;
  std::istringstream in(code);
  std::string part;
  const auto bad = [&](const std::string& why) {
    return InvalidArgument("reading '" + code + "': " + why +
                           " (expected e.g. dy-dx,x-major,++: pair dx-dy or dy-dx, node order "
                           "x-major or y-major, signs of dx and dy ++, +-, -+ or --)");
  };
  if (code.empty()) return bad("empty");
  while (std::getline(in, part, ',')) {
    const auto b = part.find_first_not_of(" \t"), e = part.find_last_not_of(" \t");
    part = b == std::string::npos ? "" : part.substr(b, e - b + 1);
    bool* seen = nullptr;
    if (part == "dx-dy" || part == "dy-dx") {
      seen = &pair;
      r.pair_dy_dx = part == "dy-dx";
    } else if (part == "x-major" || part == "y-major") {
      seen = &order;
      r.y_major = part == "y-major";
    } else if (part.size() == 2 && (part[0] == '+' || part[0] == '-') &&
               (part[1] == '+' || part[1] == '-')) {
      seen = &signs;
      r.negate_dx = part[0] == '-';
      r.negate_dy = part[1] == '-';
    } else {
      return bad("'" + part + "' is not a part of a reading");
    }
    if (*seen) return bad("'" + part + "' gives a part a second time");
    *seen = true;
  }
  return r;
}

std::vector<CorReading> AllCorReadings() {
  std::vector<CorReading> all;
  for (int order = 0; order < 2; ++order) {
    for (int pair = 0; pair < 2; ++pair) {
      for (int sx = 0; sx < 2; ++sx) {
        for (int sy = 0; sy < 2; ++sy) all.push_back({order == 1, pair == 1, sx == 1, sy == 1});
      }
    }
  }
  return all;  // the default, all false, first
}

CorReading DocumentedReading(bool first_mirror_on_word2) {
  CorReading r;
  r.y_major = !first_mirror_on_word2;    // the outer index walks word 2
  r.pair_dy_dx = first_mirror_on_word2;  // the first element is along word 1
  r.negate_dx = true;                    // the board subtracts what is stored
  r.negate_dy = true;
  return r;
}

bool IsDocumentedReading(const CorReading& reading) {
  return reading == DocumentedReading(false) || reading == DocumentedReading(true);
}

bool FirstMirrorOnWord2(const CorReading& reading) { return reading == DocumentedReading(true); }

Eigen::Vector2d CorFile::NodeMm(int i, int j) const {
  return {(i * 1024.0 - 32768.0) / scale, (j * 1024.0 - 32768.0) / scale};
}

Eigen::Vector2d CorFile::OffsetMm(int i, int j, const CorReading& reading) const {
  const auto& s = offsets[Entry(i, j, reading)];
  double dx = reading.pair_dy_dx ? s[1] : s[0];
  double dy = reading.pair_dy_dx ? s[0] : s[1];
  if (reading.negate_dx) dx = -dx;
  if (reading.negate_dy) dy = -dy;
  return Eigen::Vector2d(dx, dy) / scale;
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
    cor.scale = Get<double>(b, kJczScale);
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
  const size_t pair_bytes = cor.format == CorFormat::kJcz2 ? 8 : 16;
  for (size_t n = 0; n < cor.offsets.size(); ++n) {
    if (cor.format == CorFormat::kJcz2) {
      cor.offsets[n] = {static_cast<double>(Get<int32_t>(b, table + 8 * n)),
                        static_cast<double>(Get<int32_t>(b, table + 8 * n + 4))};
    } else {
      cor.offsets[n] = {Get<double>(b, table + 16 * n), Get<double>(b, table + 16 * n + 8)};
    }
    for (double v : cor.offsets[n]) {
      if (!std::isfinite(v)) {
        return bad("entry " + std::to_string(n) +
                   " of 4225 holds an offset that is not a number (" + std::to_string(v) + ")");
      }
      if (std::abs(v) > kMaxOffset) {
        return bad("entry " + std::to_string(n) + " of 4225 holds an offset of " +
                   std::to_string(v) + " units, beyond the board's +-32767");
      }
    }
  }
  cor.header = b.substr(0, table);
  cor.trailer = b.substr(table + cor.offsets.size() * pair_bytes);
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
  // A header as read is written back as it was (the scale patched in, the same bytes when it
  // was not changed); otherwise insitu's: the label, zeros, the scale.
  const size_t table = cor.format == CorFormat::kJcz2 ? kJczTable : kLmcTable;
  const size_t scale_at =
      cor.format == CorFormat::kJcz2 ? kJczScale : kLabelBytes + 2 + kLmcScaleIndex * 8;
  std::string b;
  if (cor.header.size() == table) {
    b = cor.header;
  } else {
    b = Label(cor.format == CorFormat::kJcz2 ? kJczLabel : kLmcLabel);
    b.resize(table, '\0');
  }
  std::memcpy(b.data() + scale_at, &cor.scale, sizeof cor.scale);
  for (const auto& o : cor.offsets) {
    for (double v : o) {
      if (cor.format == CorFormat::kJcz2) {
        Append(&b, static_cast<int32_t>(std::lround(v)));
      } else {
        Append(&b, v);
      }
    }
  }
  if (cor.format == CorFormat::kJcz2) {
    b += cor.trailer.size() == kJczTrailer ? cor.trailer : std::string(kJczTrailer, '\0');
  } else {
    b += cor.trailer;
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

std::string ToCorrectionCsv(const CorFile& cor, const CorReading& reading) {
  char line[160];
  std::snprintf(line, sizeof line, "# from a %s .cor file, lens %.6f mm\n",
                cor.format == CorFormat::kJcz2 ? kJczLabel : kLmcLabel, cor.lens_mm());
  std::string out = line;
  out += "# " + std::string(kReadingComment) + " " + reading.Code() + " (" + reading.Name() +
         ")\nx_mm,y_mm,dx_mm,dy_mm\n";
  // 1e-10 mm is 1e-7 units on the widest lens: the CSV read back gives the stored units again.
  for (int i = 0; i < kNodes; ++i) {
    for (int j = 0; j < kNodes; ++j) {
      const Eigen::Vector2d p = cor.NodeMm(i, j);
      const Eigen::Vector2d o = cor.OffsetMm(i, j, reading);
      std::snprintf(line, sizeof line, "%.10f,%.10f,%.10f,%.10f\n", p.x(), p.y(), o.x(), o.y());
      out += line;
    }
  }
  return out;
}

Result<std::optional<CorReading>> CorReadingOfCsv(const std::string& text,
                                                  const std::string& origin) {
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  const std::string key = "# " + std::string(kReadingComment);
  while (std::getline(in, line)) {
    ++line_no;
    if (line.rfind(key, 0) != 0) continue;
    std::istringstream rest(line.substr(key.size()));
    std::string code;
    rest >> code;
    auto reading = ParseCorReading(code);
    if (!reading.ok()) {
      return reading.status().Prefixed(origin + ":" + std::to_string(line_no));
    }
    return std::optional<CorReading>(*reading);
  }
  return std::optional<CorReading>();
}

CorFile FromCorrection(const std::function<Eigen::Vector2d(double, double)>& offset_mm,
                       double lens_mm, CorFormat format, const CorReading& reading) {
  CorFile cor;
  cor.format = format;
  cor.scale = 65536.0 / lens_mm;
  cor.offsets.resize(kNodes * kNodes);
  for (int i = 0; i < kNodes; ++i) {
    for (int j = 0; j < kNodes; ++j) {
      const Eigen::Vector2d p = cor.NodeMm(i, j);
      const Eigen::Vector2d d = offset_mm(p.x(), p.y()) * cor.scale;
      // Whole units, what the board takes (+ 0.0: never a negative zero). A non-finite or huge
      // value stays as it is, for WriteCor to refuse.
      const auto units = [](double v) { return std::abs(v) < 1e15 ? std::round(v) + 0.0 : v; };
      const double dx = units(reading.negate_dx ? -d.x() : d.x());
      const double dy = units(reading.negate_dy ? -d.y() : d.y());
      cor.offsets[Entry(i, j, reading)] =
          reading.pair_dy_dx ? std::array<double, 2>{dy, dx} : std::array<double, 2>{dx, dy};
    }
  }
  return cor;
}

Eigen::Vector2d BoardWordsOf(const Eigen::Vector2d& point_mm, const BoardOptions& board) {
  double a = board.flip_x ? -point_mm.x() : point_mm.x();
  double b = board.flip_y ? -point_mm.y() : point_mm.y();
  if (board.swap_xy) std::swap(a, b);
  const double scale = 65536.0 / board.lens_mm;
  return {32768.0 + a * scale, 32768.0 + b * scale};
}

Eigen::Vector2d GalvoMmOf(const Eigen::Vector2d& words, const BoardOptions& board) {
  const double scale = 65536.0 / board.lens_mm;
  double a = (words.x() - 32768.0) / scale, b = (words.y() - 32768.0) / scale;
  if (board.swap_xy) std::swap(a, b);
  return {board.flip_x ? -a : a, board.flip_y ? -b : b};
}

CorFile BoardTableFromDrive(const std::function<Eigen::Vector2d(const Eigen::Vector2d&)>& drive_mm,
                            const BoardOptions& board, CorFormat format) {
  CorFile cor;
  cor.format = format;
  cor.scale = 65536.0 / board.lens_mm;
  cor.offsets.resize(kNodes * kNodes);
  const auto units = [](double v) { return std::abs(v) < 1e15 ? std::round(v) + 0.0 : v; };
  for (int outer = 0; outer < kNodes; ++outer) {
    for (int inner = 0; inner < kNodes; ++inner) {
      const Eigen::Vector2d w(inner * 1024.0, outer * 1024.0);
      const Eigen::Vector2d sent = BoardWordsOf(drive_mm(GalvoMmOf(w, board)), board);
      cor.offsets[static_cast<size_t>(outer) * kNodes + inner] = {units(w.x() - sent.x()),
                                                                  units(w.y() - sent.y())};
    }
  }
  return cor;
}

}  // namespace insitu::hw::lmc
