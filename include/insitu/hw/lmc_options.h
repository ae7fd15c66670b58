// What a job's `machine:` section sets for an LMC galvo board (scanner: lmc, its `lmc:` part):
// which USB board, and the board and head as installed. Positions are in the galvo frame, mm;
// the board's 16-bit units span the lens field (65536 units across, centre 0x8000). The
// encoder, the protocol, the USB transport and the board emulator stay in src/hw/lmc.
#pragma once

#include <array>
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

// The laser source the board drives: which list commands carry the power and the pulse rate.
//  * fiber (Q-switched): listQSwitchPeriod (20000 / kHz) and listMarkCurrent (power x 0xFFF);
//  * mopa: the same and the pulse width (listFiberYLPMPulseWidth, ns);
//  * co2, uv: listMarkFreq (10000 / kHz), listSetCo2FPK (the first pulse killer, 2000 / kHz,
//    twice) and listMarkPowerRatio (the duty: 200 x power % / kHz); a uv source may take the
//    power inverted (power_invert).
enum class Source { kFiber, kMopa, kCo2, kUv };
const char* SourceName(Source s);  // "fiber", "mopa", "co2", "uv"

// What the board is told when it opens, after Reset and the correction table (EzCad2's start-up,
// as captured and replayed by open drivers): the defaults are the values EzCad sends.
struct StartupOptions {
  uint16_t control_mode = 0;  // SetControlMode
  uint16_t laser_mode = 1;    // SetLaserMode
  uint16_t delay_mode = 1;    // SetDelayMode
  uint16_t timing_mode = 1;   // SetTiming
  uint16_t standby_1 = 2000;  // SetStandby: the standby pulses that keep a fibre laser ready
  uint16_t standby_2 = 20;
  uint16_t first_pulse_killer = 200;                  // SetFirstPulseKiller
  uint16_t pwm_half_period = 125;                     // SetPwmHalfPeriod
  uint16_t pwm_pulse_width = 125;                     // SetPwmPulseWidth
  std::array<uint16_t, 4> fpk2{0x0FFB, 1, 409, 100};  // SetFpkParam2
  std::array<uint16_t, 4> fly_res{0, 99, 1000, 25};   // SetFlyRes (marking on the fly)
  uint16_t analog_port_1 = 0x07FF;                    // WriteAnalogPort1
};

struct BoardOptions {
  Source source = Source::kFiber;
  // A MOPA source's pulse width (ns, 1..65535; its data sheet lists the widths it has); 0 for
  // any other source (refused there: it means nothing to them).
  double pulse_width_ns = 0.0;
  bool power_invert = false;  // a uv source taking 100 - power (only uv)
  StartupOptions startup;
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
  // The longest a list may keep the board busy, s; 0 (default): as long as it does (a long
  // list legitimately runs for hours; progress and cancel work throughout).
  double list_timeout_s = 0.0;
  int packets_before_start = 3;  // then the rest are streamed as the board reports READY

  Status Validate() const;
};

}  // namespace insitu::hw::lmc
