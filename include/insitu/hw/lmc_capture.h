// USB captures of an LMC board's traffic, read and written, so that what EzCad2 and insitu send
// a board can be compared on the machine itself (`insitu lmc decode FILE`).
//
// Read: usbmon text (Linux, /sys/kernel/debug/usb/usbmon/<bus>u), pcap and pcapng files holding
// Linux usbmon packets (link types 189 and 220: Wireshark or tcpdump on a usbmonN interface) or
// Windows USBPcap packets (link type 249: Wireshark on Windows, where EzCad2 runs). What counts is
// what the host sent the board: bulk OUT transfers to endpoint 2, 12-byte single commands and
// 3072-byte list packets. usbmon text keeps only the first 32 bytes of a transfer (the
// kernel's limit), so its list packets are cut: the decode says so and names the pcapng way.
// Written: insitu's own traffic (`lmc.capture: FILE` in a job's machine section), as pcapng
// (Linux usbmon, link type 220) or, for a `.txt`/`.mon` name, usbmon text with every byte.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::hw::lmc {

// One transfer the host sent the board (bulk OUT, endpoint 2): the bytes the capture holds and
// the length the host sent (larger when the capture cut it).
struct CapturedTransfer {
  std::vector<uint8_t> data;
  size_t length = 0;
  int bus = 0, device = 0;  // the USB device it went to (0: not in the capture)
};

// The OUT transfers of a capture, in order. `name` only names the capture in errors. Errors:
// parse_error (not a usbmon text, pcap or pcapng capture; a truncated block; a link type
// other than usbmon or USBPcap, named).
Result<std::vector<CapturedTransfer>> ReadCapture(const std::string& bytes,
                                                  const std::string& name);

// The traffic as `insitu lmc decode` prints it, of the board: the device whose OUT transfers
// to endpoint 2 are all commands and list packets, the most of them (others named, skipped).
// Each list the board received (from a ResetList
// to the next), one command a line as FormatCommands writes them and as a job's galvo_list.txt
// holds the marking list: its commands up to and including its end-of-list (the padding after
// it is not the list). Single commands are comment lines ("# GotoXY 8000 8000 ..."), runs of
// status polls and correction lines counted on one line; "# list N: ..." heads each list. So
// the lines that are not comments are exactly the lists.
std::string DecodeTraffic(const std::vector<CapturedTransfer>& transfers);

// Reads the file and decodes it. Errors: not_found, ReadCapture's.
Result<std::string> DecodeCaptureFile(const std::string& path);

}  // namespace insitu::hw::lmc
