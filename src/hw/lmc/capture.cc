// USB captures of an LMC board's traffic (insitu/hw/lmc_capture.h): usbmon text, pcap and
// pcapng with Linux usbmon or Windows USBPcap packets read; insitu's own traffic written.
//
// Formats, from their public specifications: the kernel's Documentation/usb/usbmon.rst (text
// lines; the binary packet header, 48 bytes, 64 for the mmapped interface), the pcap and
// pcapng file formats (IETF drafts: section header, interface description, enhanced and simple
// packet blocks; link types 189 USB_LINUX, 220 USB_LINUX_MMAPPED, 249 USBPCAP) and USBPcap's
// packet header (27 bytes for a bulk transfer).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <sstream>

#include "hw/lmc/lmc.h"
#include "insitu/hw/lmc_capture.h"

namespace insitu::hw::lmc {
namespace {

constexpr uint8_t kOutEndpoint = 0x02;

// Little- or big-endian reads from a byte buffer, bounds checked by the caller.
struct Bytes {
  const uint8_t* p;
  size_t n;
  bool swap = false;  // the file's byte order is not the reader's (big-endian pcap)
  uint16_t U16(size_t at) const {
    const uint16_t v = static_cast<uint16_t>(p[at] | (p[at + 1] << 8));
    return swap ? static_cast<uint16_t>((v >> 8) | (v << 8)) : v;
  }
  uint32_t U32(size_t at) const {
    const uint32_t v = static_cast<uint32_t>(p[at]) | (static_cast<uint32_t>(p[at + 1]) << 8) |
                       (static_cast<uint32_t>(p[at + 2]) << 16) |
                       (static_cast<uint32_t>(p[at + 3]) << 24);
    return swap ? __builtin_bswap32(v) : v;
  }
};

Status Truncated(const std::string& name, size_t at) {
  return ParseError(name + ": the capture ends inside a block at byte " + std::to_string(at));
}

// One captured packet of link type `link`: the OUT data it carries to endpoint 2, if any.
// usbmon packets are in the capturing host's byte order (little-endian on x86 and ARM hosts);
// USBPcap's are little-endian.
void TakePacket(uint32_t link, const uint8_t* d, size_t n, size_t original,
                std::vector<CapturedTransfer>* out) {
  if (link == 189 || link == 220) {
    const size_t header = link == 220 ? 64 : 48;
    if (n < header) return;
    const Bytes b{d, n};
    const char type = static_cast<char>(d[8]);
    const uint8_t xfer = d[9], endpoint = d[10];
    const bool has_data = d[15] == 0;
    const uint32_t length = b.U32(32);
    if (type != 'S' || xfer != 3 || endpoint != kOutEndpoint || !has_data) return;
    CapturedTransfer t;
    t.data.assign(d + header, d + n);
    t.length = std::max<size_t>(length, t.data.size());
    t.bus = b.U16(12);
    t.device = d[11];
    (void)original;
    out->push_back(std::move(t));
  } else if (link == 249) {
    if (n < 27) return;
    const Bytes b{d, n};
    const uint16_t header = b.U16(0);
    const bool completion = (d[16] & 1) != 0;  // PDO -> FDO: the answer, no OUT data
    const uint8_t endpoint = d[21], transfer = d[22];
    const uint32_t length = b.U32(23);
    if (completion || transfer != 3 || endpoint != kOutEndpoint || header < 27 || header > n) {
      return;
    }
    CapturedTransfer t;
    t.data.assign(d + header, d + n);
    t.length = std::max<size_t>(length, t.data.size());
    t.bus = b.U16(17);
    t.device = b.U16(19);
    out->push_back(std::move(t));
  }
}

Status CheckLink(uint32_t link, const std::string& name) {
  if (link == 189 || link == 220 || link == 249) return Status::Ok();
  return ParseError(name + ": link type " + std::to_string(link) +
                    " is not USB (189/220: Linux usbmon, 249: USBPcap)");
}

Result<std::vector<CapturedTransfer>> ReadPcap(const std::string& s, const std::string& name) {
  const auto* p = reinterpret_cast<const uint8_t*>(s.data());
  Bytes b{p, s.size()};
  const uint32_t magic = b.U32(0);
  b.swap = magic == 0xd4c3b2a1 || magic == 0x4d3cb2a1;
  if (s.size() < 24) return Truncated(name, 0);
  const uint32_t link = b.U32(20) & 0xFFFF;
  INSITU_RETURN_IF_ERROR(CheckLink(link, name));
  std::vector<CapturedTransfer> out;
  for (size_t at = 24; at < s.size();) {
    if (at + 16 > s.size()) return Truncated(name, at);
    const uint32_t captured = b.U32(at + 8), original = b.U32(at + 12);
    if (at + 16 + captured > s.size()) return Truncated(name, at);
    TakePacket(link, p + at + 16, captured, original, &out);
    at += 16 + captured;
  }
  return out;
}

Result<std::vector<CapturedTransfer>> ReadPcapng(const std::string& s, const std::string& name) {
  const auto* p = reinterpret_cast<const uint8_t*>(s.data());
  Bytes b{p, s.size()};
  std::vector<uint32_t> links;  // per interface of the current section
  std::vector<CapturedTransfer> out;
  for (size_t at = 0; at < s.size();) {
    if (at + 12 > s.size()) return Truncated(name, at);
    uint32_t type = b.U32(at);
    if (type == 0x0A0D0D0A) {  // a section: its byte order from the byte-order magic
      b.swap = false;
      const uint32_t bom = b.U32(at + 8);
      if (bom == 0x4D3C2B1A) {
        b.swap = true;
      } else if (bom != 0x1A2B3C4D) {
        return ParseError(name + ": a pcapng section without its byte-order magic at byte " +
                          std::to_string(at));
      }
      links.clear();
    }
    const uint32_t length = b.U32(at + 4);
    if (length < 12 || length % 4 != 0 || at + length > s.size()) return Truncated(name, at);
    const uint8_t* body = p + at + 8;
    const size_t body_n = length - 12;
    if (type == 1) {  // interface description: link type, snap length
      if (body_n < 8) return Truncated(name, at);
      const uint32_t link = b.U16(at + 8);
      INSITU_RETURN_IF_ERROR(CheckLink(link, name));
      links.push_back(link);
    } else if (type == 6) {  // enhanced packet: interface, time, lengths, data
      if (body_n < 20) return Truncated(name, at);
      const uint32_t iface = b.U32(at + 8);
      const uint32_t captured = b.U32(at + 20), original = b.U32(at + 24);
      if (iface >= links.size()) {
        return ParseError(name + ": a packet of interface " + std::to_string(iface) +
                          " before its description");
      }
      if (static_cast<size_t>(captured) > body_n - 20) return Truncated(name, at);
      TakePacket(links[iface], body + 20, captured, original, &out);
    } else if (type == 3) {  // simple packet: interface 0
      if (body_n < 4 || links.empty()) return Truncated(name, at);
      const uint32_t original = b.U32(at + 8);
      TakePacket(links[0], body + 4, std::min<size_t>(original, body_n - 4), original, &out);
    }
    at += length;
  }
  return out;
}

// usbmon text: "<tag> <timestamp> <S|C|E> <Bo:bus:dev:ep or Bo:dev:ep> <status> <length> =
// <data words>". Words are the bytes in the order of the transfer, up to 8 hex digits each.
Result<std::vector<CapturedTransfer>> ReadUsbmonText(const std::string& s,
                                                     const std::string& name) {
  std::vector<CapturedTransfer> out;
  std::istringstream in(s);
  std::string line;
  int number = 0, events = 0;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream w(line);
    std::string tag, timestamp, event, address, status, length_text, equals;
    if (!(w >> tag >> timestamp >> event >> address)) continue;
    if (event != "S" && event != "C" && event != "E") continue;
    ++events;
    if (event != "S" || address.rfind("Bo:", 0) != 0) continue;
    // Bo:bus:device:endpoint, or Bo:device:endpoint (older kernels, one bus per file).
    std::vector<long> fields;
    for (size_t at = 3; at <= address.size();) {
      const size_t next = std::min(address.find(':', at), address.size());
      fields.push_back(std::strtol(address.substr(at, next - at).c_str(), nullptr, 10));
      at = next + 1;
    }
    if (fields.size() < 2 || fields.back() != kOutEndpoint) continue;
    if (!(w >> status >> length_text)) continue;
    CapturedTransfer t;
    t.length = static_cast<size_t>(std::strtoul(length_text.c_str(), nullptr, 10));
    t.bus = fields.size() >= 3 ? static_cast<int>(fields[0]) : 0;
    t.device = static_cast<int>(fields[fields.size() - 2]);
    if (!(w >> equals) || equals != "=") {  // no data captured ('<', '>' or nothing)
      out.push_back(std::move(t));
      continue;
    }
    std::string word;
    while (w >> word) {
      if (word.size() % 2 != 0 || word.size() > 8 ||
          word.find_first_not_of("0123456789abcdefABCDEF") != std::string::npos) {
        return ParseError(name + ":" + std::to_string(number) + ": '" + word +
                          "' is not a usbmon data word");
      }
      for (size_t i = 0; i < word.size(); i += 2) {
        t.data.push_back(static_cast<uint8_t>(std::stoul(word.substr(i, 2), nullptr, 16)));
      }
    }
    out.push_back(std::move(t));
  }
  if (events == 0) {
    return ParseError(name + ": no usbmon text events (S, C or E lines), and not pcap or pcapng");
  }
  return out;
}

const char* SingleName(uint16_t op) {
  switch (op) {
    case kDisableLaser:
      return "DisableLaser";
    case kEnableLaser:
      return "EnableLaser";
    case kExecuteList:
      return "ExecuteList";
    case kSetPwmPulseWidth:
      return "SetPwmPulseWidth";
    case kGetVersion:
      return "GetVersion";
    case kGetSerialNo:
      return "GetSerialNo";
    case kGotoXY:
      return "GotoXY";
    case kWriteCorLine:
      return "WriteCorLine";
    case kResetList:
      return "ResetList";
    case kWriteCorTable:
      return "WriteCorTable";
    case kSetControlMode:
      return "SetControlMode";
    case kSetDelayMode:
      return "SetDelayMode";
    case kSetEndOfList:
      return "SetEndOfList";
    case kSetFirstPulseKiller:
      return "SetFirstPulseKiller";
    case kSetLaserMode:
      return "SetLaserMode";
    case kSetTiming:
      return "SetTiming";
    case kSetStandby:
      return "SetStandby";
    case kSetPwmHalfPeriod:
      return "SetPwmHalfPeriod";
    case kStopExecute:
      return "StopExecute";
    case kWritePort:
      return "WritePort";
    case kWriteAnalogPort1:
      return "WriteAnalogPort1";
    case kSetFpkParam2:
      return "SetFpkParam2";
    case kSetFlyRes:
      return "SetFlyRes";
    case kFiberSetMo:
      return "Fiber_SetMo";
    case kEnableZ:
      return "EnableZ";
    case kReset:
      return "Reset";
    default:
      return nullptr;
  }
}

std::string SingleLine(const Command& c) {
  char line[96];
  const char* n = SingleName(c[0]);
  if (n != nullptr) {
    std::snprintf(line, sizeof line, "# %-19s %04x %04x %04x %04x %04x\n", n, c[1], c[2], c[3],
                  c[4], c[5]);
  } else {
    std::snprintf(line, sizeof line, "# op %04x             %04x %04x %04x %04x %04x\n", c[0], c[1],
                  c[2], c[3], c[4], c[5]);
  }
  return line;
}

}  // namespace

Result<std::vector<CapturedTransfer>> ReadCapture(const std::string& bytes,
                                                  const std::string& name) {
  if (bytes.size() >= 4) {
    const Bytes b{reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()};
    const uint32_t magic = b.U32(0);
    if (magic == 0x0A0D0D0A) return ReadPcapng(bytes, name);
    if (magic == 0xa1b2c3d4 || magic == 0xd4c3b2a1 || magic == 0xa1b23c4d || magic == 0x4d3cb2a1) {
      return ReadPcap(bytes, name);
    }
  }
  return ReadUsbmonText(bytes, name);
}

std::string DecodeTraffic(const std::vector<CapturedTransfer>& all) {
  // The board among the capture's devices (a capture of a whole bus holds a disk's or another
  // device's bulk OUT endpoint 2 too): of the devices whose OUT transfers are all 12-byte
  // commands or 3072-byte list packets, the one with the most; the others are named.
  std::map<std::pair<int, int>, std::pair<size_t, bool>> devices;  // count, LMC-like
  for (const CapturedTransfer& t : all) {
    auto& [count, like] = devices.try_emplace({t.bus, t.device}, 0, true).first->second;
    ++count;
    like = like && (t.length == kCommandBytes || t.length == kPacketBytes);
  }
  std::pair<int, int> board{-1, -1};
  size_t best = 0;
  bool best_like = false;
  for (const auto& [id, info] : devices) {
    if ((info.second && !best_like) || (info.second == best_like && info.first > best)) {
      board = id, best = info.first, best_like = info.second;
    }
  }
  std::vector<CapturedTransfer> transfers;
  for (const CapturedTransfer& t : all) {
    if (std::make_pair(t.bus, t.device) == board) transfers.push_back(t);
  }
  std::string preamble;
  if (devices.size() > 1) {
    preamble = "# the board: bus " + std::to_string(board.first) + " device " +
               std::to_string(board.second) + "; skipped:";
    for (const auto& [id, info] : devices) {
      if (id == board) continue;
      preamble += " bus " + std::to_string(id.first) + " device " + std::to_string(id.second) +
                  " (" + std::to_string(info.first) + " transfers)";
    }
    preamble += "\n";
  }
  // The output in pieces: a list is written where its first packet came (the single commands
  // sent while it streamed and ran follow it), once its end is known.
  std::vector<std::string> pieces(1);
  // A run of the same uninteresting single command (status polls, correction lines) as one
  // counted line.
  uint16_t run_op = 0;
  int run_count = 0;
  const auto flush_run = [&] {
    if (run_count == 0) return;
    pieces.back() +=
        std::string("# ") + SingleName(run_op) + " x" + std::to_string(run_count) +
        (run_op == kGetVersion ? " (status polls)\n" : " (the correction table's lines)\n");
    run_count = 0;
  };
  int lists = 0;
  bool in_list = false, ended = false, cut = false, any_cut = false;
  size_t packets = 0, slot = 0;
  std::vector<Command> list;
  const auto end_list = [&] {
    if (!in_list) return;
    char head[128];
    std::snprintf(head, sizeof head, "# list %d: %zu packet%s, %zu command%s%s\n", ++lists, packets,
                  packets == 1 ? "" : "s", list.size(), list.size() == 1 ? "" : "s",
                  cut     ? " (cut by the capture)"
                  : ended ? ""
                          : ", no end-of-list (the board waits, or runs on)");
    pieces[slot] = head + FormatCommands(list);
    in_list = ended = cut = false;
    packets = 0;
    list.clear();
  };
  for (const CapturedTransfer& t : transfers) {
    if (t.length == kPacketBytes) {
      flush_run();
      if (!in_list) {  // its place in the output, and what follows it
        in_list = true;
        slot = pieces.size();
        pieces.emplace_back();
        pieces.emplace_back();
      }
      ++packets;
      if (t.data.size() < kPacketBytes) cut = any_cut = true;
      for (size_t k = 0; k + kCommandBytes <= t.data.size() && !ended; k += kCommandBytes) {
        list.push_back(DecodeCommand(t.data.data() + k));
        ended = list.back()[0] == kEndOfList;
      }
      continue;
    }
    if (t.data.size() < kCommandBytes) {
      flush_run();
      pieces.back() += "# a transfer of " + std::to_string(t.length) + " bytes (" +
                       std::to_string(t.data.size()) +
                       " captured): neither a command nor a list packet\n";
      continue;
    }
    const Command c = DecodeCommand(t.data.data());
    if (c[0] == kResetList) {
      flush_run();
      end_list();
    }
    if (c[0] == kGetVersion || c[0] == kWriteCorLine) {
      if (run_count > 0 && run_op != c[0]) flush_run();
      run_op = c[0];
      ++run_count;
      continue;
    }
    flush_run();
    pieces.back() += SingleLine(c);
  }
  flush_run();
  end_list();
  std::string out = preamble;
  for (const std::string& p : pieces) out += p;
  if (any_cut) {
    out +=
        "# usbmon text keeps the first 32 bytes of a transfer: capture the lists whole with "
        "Wireshark or tcpdump on the usbmon interface (pcapng), or USBPcap on Windows\n";
  }
  return out;
}

Result<std::string> DecodeCaptureFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return NotFound("cannot open capture " + path);
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  INSITU_ASSIGN_OR_RETURN(const auto transfers, ReadCapture(bytes, path));
  return DecodeTraffic(transfers);
}

namespace {

// A transport that writes what passes through it to a capture file: every write as a bulk OUT
// submission to endpoint 2 with its data, every read as a bulk IN completion from 0x88.
class CapturingTransport : public Transport {
 public:
  CapturingTransport(std::unique_ptr<Transport> inner, std::ofstream file, bool text)
      : inner_(std::move(inner)), file_(std::move(file)), text_(text) {
    if (!text_) {
      // Section header (little-endian, version 1.0, unknown section length) and one interface:
      // Linux usbmon, mmapped header (link type 220), snap length 65536.
      Block(0x0A0D0D0A, {0x1A2B3C4D, 0x00000001, 0xFFFFFFFF, 0xFFFFFFFF}, nullptr, 0);
      Block(1, {220u | (0u << 16), 65536}, nullptr, 0);
    }
  }
  Status Write(const uint8_t* data, size_t size) override {
    Record('S', kOutEndpoint, data, size);
    return inner_->Write(data, size);
  }
  Status Read(uint8_t* data, size_t size) override {
    const Status s = inner_->Read(data, size);
    if (s.ok()) Record('C', 0x88, data, size);
    return s;
  }
  std::string Describe() const override { return inner_->Describe(); }

 private:
  void Block(uint32_t type, const std::vector<uint32_t>& words, const uint8_t* data, size_t n) {
    const size_t padded = (n + 3) / 4 * 4;
    const uint32_t length = static_cast<uint32_t>(12 + 4 * words.size() + padded);
    Put32(type);
    Put32(length);
    for (uint32_t w : words) Put32(w);
    if (n > 0) file_.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(n));
    for (size_t i = n; i < padded; ++i) file_.put('\0');
    Put32(length);
  }
  void Put32(uint32_t v) {
    const char b[4] = {static_cast<char>(v), static_cast<char>(v >> 8), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 24)};
    file_.write(b, 4);
  }
  void Record(char event, uint8_t endpoint, const uint8_t* data, size_t size) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    const auto us = std::chrono::duration_cast<std::chrono::microseconds>(now).count();
    ++id_;
    if (text_) {
      char head[96];
      std::snprintf(head, sizeof head,
                    "%08llx %llu %c B%c:1:001:%d %d %zu =", static_cast<unsigned long long>(id_),
                    static_cast<unsigned long long>(us % 4294967296ULL), event,
                    endpoint & 0x80 ? 'i' : 'o', endpoint & 0x7F, event == 'S' ? -115 : 0, size);
      file_ << head;
      for (size_t i = 0; i < size; i += 4) {
        file_ << ' ';
        for (size_t j = i; j < std::min(size, i + 4); ++j) {
          char hex[3];
          std::snprintf(hex, sizeof hex, "%02x", data[j]);
          file_ << hex;
        }
      }
      file_ << '\n';
    } else {
      uint8_t header[64] = {};
      for (int i = 0; i < 8; ++i) header[i] = static_cast<uint8_t>(id_ >> (8 * i));
      header[8] = static_cast<uint8_t>(event);
      header[9] = 3;  // bulk
      header[10] = endpoint;
      header[11] = 1;    // device 1
      header[12] = 1;    // bus 1
      header[14] = '-';  // no setup packet
      header[15] = 0;    // data present
      const int64_t sec = us / 1000000;
      const int32_t usec = static_cast<int32_t>(us % 1000000);
      std::memcpy(header + 16, &sec, 8);
      std::memcpy(header + 24, &usec, 4);
      const int32_t status = event == 'S' ? -115 : 0;  // -EINPROGRESS at submission
      const uint32_t length = static_cast<uint32_t>(size);
      std::memcpy(header + 28, &status, 4);
      std::memcpy(header + 32, &length, 4);
      std::memcpy(header + 36, &length, 4);
      std::vector<uint8_t> packet(header, header + 64);
      packet.insert(packet.end(), data, data + size);
      const uint64_t ts = static_cast<uint64_t>(us);
      Block(6,
            {0, static_cast<uint32_t>(ts >> 32), static_cast<uint32_t>(ts),
             static_cast<uint32_t>(packet.size()), static_cast<uint32_t>(packet.size())},
            packet.data(), packet.size());
    }
    file_.flush();
  }

  std::unique_ptr<Transport> inner_;
  std::ofstream file_;
  bool text_;
  std::mutex mutex_;
  uint64_t id_ = 0;
};

}  // namespace

Result<std::unique_ptr<Transport>> Capturing(std::unique_ptr<Transport> inner,
                                             const std::string& path) {
  std::error_code ec;
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) return NotFound("cannot write the USB capture " + path);
  const bool text = path.size() >= 4 && (path.substr(path.size() - 4) == ".txt" ||
                                         path.substr(path.size() - 4) == ".mon");
  return std::unique_ptr<Transport>(
      std::make_unique<CapturingTransport>(std::move(inner), std::move(file), text));
}

}  // namespace insitu::hw::lmc
