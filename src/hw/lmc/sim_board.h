// An LMC board emulated at the USB transport: it decodes the bytes the LMC backend sends
// (single commands, 3072-byte list packets), answers with status replies as the board does,
// and executes lists on the simulated scan head (sim::SimWorld), so a marking job runs end to
// end through the real encoder and protocol. The board's emulated memory and the head's
// geometry (lens, axes, focus shifter) come from `options`, as the installed board would have
// them. Private to src/hw (the backend's folder, machine.cc and its tests).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "hw/lmc/lmc.h"
#include "insitu/sim/world.h"

namespace insitu::hw::lmc {

// What the emulated board received (for tests): counts and the last correction table.
struct SimBoardLog {
  int single_commands = 0;
  int packets = 0;
  int lists_executed = 0;
  int end_of_lists = 0;  // end-of-list commands executed: one per list that ended
  int starved = 0;       // times a list's commands ran out before its end (the board waits)
  int stops = 0;
  bool laser_enabled = false;
  bool mo_open = false;  // the fibre laser's master oscillator
  uint16_t ports = 0;
  uint16_t last_goto_distance = 0;                 // the last GotoXY's distance word (p4)
  std::vector<std::array<int32_t, 2>> correction;  // as uploaded, signed
  bool correction_blank = false;                   // WriteCorTable 0: a blank table
  // The start-up a board needs before it runs a list (Reset, the correction table, the modes,
  // standby, first pulse killer and PWM: StartupCommands) received since power-up or the last
  // Reset.
  bool started = false;
  int resets = 0;
  // What the board would not accept, one line each: a list executed before the start-up, an
  // opcode it does not know. Tests expect none.
  std::vector<std::string> rejected;
};

class SimBoard : public Transport {
 public:
  SimBoard(std::shared_ptr<sim::SimWorld> world, BoardOptions options);
  ~SimBoard() override;

  Status Write(const uint8_t* data, size_t size) override;
  Status Read(uint8_t* data, size_t size) override;
  std::string Describe() const override { return "simulated LMC board"; }

  SimBoardLog log() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu::hw::lmc
