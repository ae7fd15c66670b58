// What a job's `machine:` section sets for an LMC galvo board (scanner: lmc, its `lmc:` part):
// which USB board, and the board and head as installed. Positions are in the galvo frame, mm;
// the board's 16-bit units span the lens field (65536 units across, centre 0x8000). The
// encoder, the protocol, the USB transport and the board emulator stay in src/hw/lmc.
#pragma once

#include <cstdint>

#include "insitu/core/status.h"

namespace insitu::hw::lmc {

// Which USB board to open: by VID/PID, and by bus and address to pick one of several.
struct UsbSelector {
  uint16_t vid = 0x9588;
  uint16_t pid = 0x9899;
  int bus = -1;          // -1: any
  int address = -1;      // -1: any
  int timeout_ms = 100;  // 1..10000 (libusb's 0 would wait forever)
  int retries = 3;       // 0..10 per transfer, on timeout

  Status Validate() const;
};

enum class Focus { kNone, kDaZWord };

struct BoardOptions {
  double lens_mm = 110.0;  // field size across the 65536 units
  bool swap_xy = false;    // axis order and sign differ between boards and heads
  bool flip_x = false;
  bool flip_y = false;
  Focus focus = Focus::kNone;
  double z_units_per_mm = 0.0;       // focus: da_z_word: Z DA word units per mm of focus shift
  double focus_range_mm = 0.0;       // +- focus travel of the shifter
  uint16_t list_ports = 0x0001;      // port word at the start of a marking list
  uint16_t pointer_port = 0x0100;    // the red pointer's output bit
  // The output bit wired to the side camera's trigger input (0: none). A triggered scan runs
  // as one list that raises it for trigger_pulse_us on each line, once the mirrors settled.
  uint16_t trigger_port = 0;
  double trigger_pulse_us = 100.0;   // 10..1000, in 10 us units; cameras need a few us
  double open_mo_delay_us = 8000.0;  // the fibre laser's master oscillator settles
  double polygon_delay_us = 100.0;   // sent in 10 us units
  int poll_ms = 2;                   // status poll period while a list runs
  double list_timeout_s = 3600.0;
  int packets_before_start = 3;  // then the rest are streamed as the board reports READY

  Status Validate() const;
};

}  // namespace insitu::hw::lmc
