// BJJCZ "LMC" (EzCad2-class) galvo boards over USB: the list encoder, the board protocol and a
// Scanner on top of them, behind a byte transport so the same code drives a real board
// (libusb) or the board emulator (sim_board.h). Private to src/hw (the backend's folder,
// machine.cc and its tests); the options a job sets are in insitu/hw/lmc_options.h.
//
// Protocol facts (docs/hardware.md, "LMC"): single commands are 12 bytes, six little-endian
// uint16 (opcode, p1..p5), answered by 8 bytes whose word 3 is the status (BUSY 0x04,
// READY 0x20); lists go out in 3072-byte packets of 256 such commands, the list always ended by
// an end-of-list (0x8002) and its last packet padded with more. Positions are 16-bit, 65536
// units across the lens field, centre 0x8000.
//
// The RTC-style GalvoList maps onto list opcodes: the list's parameters first (speeds in units
// per ms, the source's power and pulse-rate words (Source), laser on/off delays and the
// polygon delay in us), then JumpTo/MarkTo with the straight distance from the previous point,
// the JumpDelay before the first jump (a parameter, as on the board: the wait after every jump
// from there on) and a DelayTime (10 us units) after each mark sequence for the list's mark
// delay. z (focus) goes out as the board's Z DA word (0x8029) before a point whose z changed,
// when the head has a focus shifter on that output (focus: da_z_word); its scale is the
// shifter's, from its data sheet.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/hw/lmc_options.h"
#include "insitu/hw/scanner.h"

namespace insitu::hw::lmc {

// List opcodes.
enum ListOp : uint16_t {
  kJumpTo = 0x8001,
  kEndOfList = 0x8002,
  kDelayTime = 0x8004,
  kMarkTo = 0x8005,
  kJumpSpeed = 0x8006,
  kLaserOnDelay = 0x8007,
  kLaserOffDelay = 0x8008,
  kMarkFreq = 0x800A,        // co2, uv: the pulse period, 100 ns units
  kMarkPowerRatio = 0x800B,  // co2, uv: the duty
  kMarkSpeed = 0x800C,
  kJumpDelay = 0x800D,
  kPolygonDelay = 0x800F,
  kWritePortList = 0x8011,
  kMarkCurrent = 0x8012,
  kQSwitchPeriod = 0x801B,
  kSetCo2Fpk = 0x801E,        // co2, uv: the first pulse killer
  kFiberPulseWidth = 0x8026,  // mopa: the pulse width, ns
  kSetDaZWord = 0x8029,
  kReadyMark = 0x8051,
};

// Single-command opcodes.
enum SingleOp : uint16_t {
  kDisableLaser = 0x02,
  kEnableLaser = 0x04,
  kExecuteList = 0x05,
  kSetPwmPulseWidth = 0x06,
  kGetVersion = 0x07,  // the status poll
  kGetSerialNo = 0x09,
  kGotoXY = 0x0D,
  kWriteCorLine = 0x10,
  kResetList = 0x12,
  kWriteCorTable = 0x15,  // p1: 1 a table follows (4225 lines), 0 a blank one (no correction)
  kSetControlMode = 0x16,
  kSetDelayMode = 0x17,
  kSetEndOfList = 0x19,
  kSetFirstPulseKiller = 0x1A,
  kSetLaserMode = 0x1B,
  kSetTiming = 0x1C,
  kSetStandby = 0x1D,
  kSetPwmHalfPeriod = 0x1E,
  kStopExecute = 0x1F,
  kWritePort = 0x21,
  kWriteAnalogPort1 = 0x22,
  kSetFpkParam2 = 0x2E,
  kSetFlyRes = 0x32,
  kFiberSetMo = 0x33,  // the fibre laser's master oscillator: 1 open, 0 closed
  kEnableZ = 0x3A,
  kReset = 0x40,
};

constexpr uint16_t kStatusBusy = 0x04;
constexpr uint16_t kStatusReady = 0x20;
constexpr size_t kCommandBytes = 12;
constexpr size_t kReplyBytes = 8;
constexpr size_t kPacketCommands = 256;
constexpr size_t kPacketBytes = kPacketCommands * kCommandBytes;  // 3072

using Command = std::array<uint16_t, 6>;  // opcode, p1..p5

// The board's byte pipe: bulk OUT endpoint 0x02, bulk IN 0x88.
class Transport {
 public:
  Transport() = default;
  virtual ~Transport() = default;
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;

  // Errors: device_error naming the device and what failed (timeout, disconnect).
  virtual Status Write(const uint8_t* data, size_t size) = 0;
  virtual Status Read(uint8_t* data, size_t size) = 0;
  virtual std::string Describe() const = 0;  // "usb 1-4 9588:9899", "simulated board"
};

// `inner` with everything written to it and read from it recorded in a USB capture at `path`
// (insitu/hw/lmc_capture.h: pcapng, or usbmon text for a .txt or .mon name), its folder made if
// missing. Errors: not_found (the file cannot be written).
Result<std::unique_ptr<Transport>> Capturing(std::unique_ptr<Transport> inner,
                                             const std::string& path);

// Opens and claims interface 0 of the board. Errors: not_found (no such board: lists what USB
// devices with that VID:PID exist), device_error (permission: names the udev rule in
// docs/hardware.md; busy: another program holds it).
Result<std::unique_ptr<Transport>> OpenUsb(const UsbSelector& selector);

// Board units of a galvo-frame point (mm): floor(0x8000 + x * 65536 / lens), with the
// configured swap and flips. Errors: out_of_range outside the lens field.
Result<std::array<uint16_t, 2>> ToUnits(double x_mm, double y_mm, const BoardOptions& options);
// The inverse (the emulator's side).
std::array<double, 2> FromUnits(uint16_t u, uint16_t v, const BoardOptions& options);

// The list commands for `list`, starting from the head at `*position` (units; updated to where
// the list ends) and Z word `*z_word` (updated). Errors: out_of_range (a point outside the
// field or the focus range; z != 0 on a head without focus), invalid_argument (speeds, power,
// rate).
Result<std::vector<Command>> EncodeList(const GalvoList& list, const BoardOptions& options,
                                        std::array<uint16_t, 2>* position, uint16_t* z_word);
// A triggered sweep (Scanner::RunTriggeredSweep) as one list: the light list's parameters (the
// pointer port on, the laser off, the sweep's jump speed), then per line a jump to its end
// nearer the head, a DelayTime of the settle time, the trigger bit raised for
// trigger_pulse_us and lowered, and jumps back and forth along the line for the dwell, the
// last one ending where the dwell does. Errors: failed_precondition (no trigger_port),
// out_of_range (a point; a settle over the list delay's 655.35 ms), invalid_argument (the
// sweep).
Result<std::vector<Command>> EncodeTriggeredSweep(const TriggeredSweep& sweep,
                                                  const BoardOptions& options,
                                                  std::array<uint16_t, 2>* position,
                                                  uint16_t* z_word);
// 3072-byte packets: the commands, an end-of-list after them (unless they end with one), the
// last packet padded with more. A list of exactly 256 k commands takes a packet of its own for
// its end.
std::vector<std::vector<uint8_t>> Packets(const std::vector<Command>& commands);
// One 12-byte single command.
std::vector<uint8_t> SingleCommand(uint16_t op, uint16_t p1 = 0, uint16_t p2 = 0, uint16_t p3 = 0,
                                   uint16_t p4 = 0, uint16_t p5 = 0);
Command DecodeCommand(const uint8_t* bytes);
// GotoXY to `to` from where the head is (`from`): x, y, angle 0 and the straight distance in
// units (truncated, at most 0xFFFF), as a list's JumpTo carries it.
std::vector<uint8_t> GotoXY(const std::array<uint16_t, 2>& from, const std::array<uint16_t, 2>& to);
// One line per command: "listJumpTo           ba2e 45d1 0000 5248 0000".
std::string FormatCommands(const std::vector<Command>& commands);

// One single command and the board's whole 8-byte answer as four words (word 3 is the status
// for most commands; GetSerialNo answers with four words of serial). Errors: device_error.
Result<std::array<uint16_t, 4>> Query(Transport& transport, uint16_t op, uint16_t p1 = 0,
                                      uint16_t p2 = 0, uint16_t p3 = 0, uint16_t p4 = 0);
// The same for a command already encoded (SingleCommand, GotoXY).
Result<std::array<uint16_t, 4>> Query(Transport& transport, const std::vector<uint8_t>& bytes);

// What the board says of itself when it opens.
struct BoardIdentity {
  std::string serial;                 // "0x" and 16 hex digits: GetSerialNo's four words
  std::array<uint16_t, 4> version{};  // GetVersion's words (the last: its status)
  std::string Describe() const;       // "serial 0x..., version 0001 0203 0405"
};

// The start-up commands after the identity queries, in order (StartUp): Reset, the correction
// table (WriteCorTable 1 and its 4225 lines when `table` has nodes, else WriteCorTable 0: a
// blank table, the board corrects nothing), EnableLaser, SetControlMode, SetLaserMode,
// SetDelayMode, SetTiming, SetStandby, SetFirstPulseKiller, SetPwmHalfPeriod,
// SetPwmPulseWidth, FiberSetMo 0, SetFpkParam2, SetFlyRes, EnableZ, WriteAnalogPort1, EnableZ
// (EzCad2's start-up, the values options.startup's), then DisableLaser: insitu's own, so the
// laser output stays off until a job arms it. Errors: out_of_range (a correction offset).
Result<std::vector<std::vector<uint8_t>>> StartupCommands(const BoardOptions& options,
                                                          const BoardCorrection& table);
// Whether the board answers `command` (all single commands but a correction line).
bool Answered(const std::vector<uint8_t>& command);
// Opens the board as EzCad does: GetSerialNo and GetVersion (read, returned), then
// StartupCommands, each answer read, and 50 ms for the analog outputs to settle. Errors:
// device_error (transport), out_of_range (a correction offset).
Result<BoardIdentity> StartUp(Transport& transport, const BoardOptions& options,
                              const BoardCorrection& table);

// A correction table (BoardCorrection, insitu/hw/lmc_cor.h) as WriteCorTable(1) and 4225
// WriteCorLine commands (sign-magnitude words). Only WriteCorTable is answered.
Result<std::vector<std::vector<uint8_t>>> CorrectionUpload(const BoardCorrection& table);
// Sends them, reading each reply. Errors: out_of_range (an offset), device_error (transport).
Status UploadCorrection(Transport& transport, const BoardCorrection& table);

// Where the board sends a position once its correction table has had it (the documented
// convention, hw/lmc_cor.h: line k of the upload is the node at inner index k % 65 along word
// 1 and outer index k / 65 along word 2, 1024 units apart from unit 0; a line is the error
// along word 1 and along word 2, which the board subtracts, bilinear between the nodes and the
// edge's beyond them). Position words as doubles (0..65536), not rounded. An empty table: the
// words as they are.
std::array<double, 2> ApplyBoardTable(const BoardCorrection& table, double word1, double word2);
// The same in the galvo frame (mm) for a board set up as `options` (lens, swap and flips).
Eigen::Vector2d ApplyBoardTableMm(const BoardCorrection& table, const BoardOptions& options,
                                  const Eigen::Vector2d& command_mm);

// A Scanner on an LMC board. Arm/Disarm enable and disable the laser output; a marking list
// opens the fibre laser's master oscillator, is streamed (every packet once the board reports
// READY, waiting for as long as it is busy with the list before) and polled until the board is
// done, and closes it again; control.abort (checked at every poll) sends StopExecute, closes
// the oscillator, disables the laser and resets the list. The pointer sweeps with the pointer
// port on and the laser off.
// `uploaded` is the table the board was given when it opened (empty: none), so that the
// scanner can say what the galvos receive for a command (Scanner::DriveCommand).
// `identity` names the board in ScannerInfo::model. The board must have been started (StartUp);
// OpenScanner does both.
std::unique_ptr<Scanner> MakeScanner(std::unique_ptr<Transport> transport, BoardOptions options,
                                     BoardCorrection uploaded = {}, BoardIdentity identity = {});
// The board started as EzCad starts it (StartUp, with `table` or a blank one) and the Scanner on
// it. Errors: StartUp's.
Result<std::unique_ptr<Scanner>> OpenScanner(std::unique_ptr<Transport> transport,
                                             BoardOptions options, BoardCorrection table = {});

}  // namespace insitu::hw::lmc
