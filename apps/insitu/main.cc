// insitu: the operator's command line. Runs job files against the machine they name.
//   insitu run JOB.yaml [--out DIR] [--set dotted.key=value ...]
//   insitu diagnose DATA [--out DIR]             DATA: field CSV, correction CSV or .cor
//   insitu cor import FILE.cor --out TABLE.csv [--reading R]   an EzCad correction as insitu's
//                                                 field table, read as the head model explains
//   insitu cor export TABLE.csv --lens MM [--format jcz|lmc1] [--reading R] --out FILE.cor
// Exit codes: 0 done, 1 device or job failure while running (the report says what), 2 bad input
// (command line, job file, --set, calibration, pattern or data file), 130 interrupted.
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <vector>

#include "insitu/core/file.h"
#include "insitu/core/log.h"
#include "insitu/fit/cor_physics.h"
#include "insitu/hw/lmc_capture.h"
#include "insitu/hw/lmc_cor.h"
#include "insitu/job/cor_reading.h"
#include "insitu/job/diagnose_job.h"
#include "insitu/job/job_file.h"
#include "insitu/job/pattern_inspect.h"
#include "insitu/job/runner.h"
#include "insitu/pattern/correction_table.h"

#ifndef INSITU_VERSION
#define INSITU_VERSION "0.0.0"
#endif

namespace {

std::atomic<bool> g_cancel{false};

void OnSignal(int) { g_cancel.store(true); }

int ExitCodeFor(const insitu::Status& st) {
  switch (st.code()) {
    case insitu::StatusCode::kInvalidArgument:
    case insitu::StatusCode::kParseError:
    case insitu::StatusCode::kNotFound:
    case insitu::StatusCode::kOutOfRange:
    case insitu::StatusCode::kFailedPrecondition:
      return 2;
    case insitu::StatusCode::kCancelled:
      return 130;
    default:
      return 1;
  }
}

// The operator of a cell with `machine.operator: person`, at this terminal: the request on
// stderr; "done" (or Enter) when it is done, "abort" to stop the job; anything else asks again.
// What was typed before the request is discarded (a key pressed early confirms nothing).
// Ctrl-C interrupts the wait as it does a job; no one to answer (stdin closed) ends it too.
insitu::Status AskAtConsole(const std::string& request) {
  using insitu::Status;
  using insitu::StatusCode;
  if (isatty(STDIN_FILENO)) tcflush(STDIN_FILENO, TCIFLUSH);
  for (;;) {
    std::fprintf(stderr, "\noperator: %s\n  done (Enter) or abort: ", request.c_str());
    std::fflush(stderr);
    std::string line;
    for (;;) {
      if (g_cancel.load()) {
        return Status(StatusCode::kCancelled, "interrupted at the operator's prompt");
      }
      pollfd in{STDIN_FILENO, POLLIN, 0};
      const int ready = poll(&in, 1, 200);
      if (ready < 0 && errno == EINTR) continue;
      if (ready < 0) {
        return insitu::DeviceError(std::string("reading the terminal: ") + std::strerror(errno));
      }
      if (ready == 0) continue;
      char c = 0;
      const ssize_t n = read(STDIN_FILENO, &c, 1);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        return Status(StatusCode::kCancelled,
                      "no operator answered (standard input closed) to: " + request);
      }
      if (c == '\n') break;
      line += c;
    }
    line.erase(0, line.find_first_not_of(" \t\r"));
    line.erase(line.find_last_not_of(" \t\r") + 1);
    if (line.empty() || line == "done" || line == "d") return Status::Ok();
    if (line == "abort" || line == "a") {
      return Status(StatusCode::kCancelled, "the operator aborted at: " + request);
    }
    std::fprintf(stderr, "  '%s' is neither done nor abort\n", line.c_str());
  }
}

int Run(const std::string& job_path, const std::string& out_dir,
        const std::vector<std::string>& sets) {
  auto job = insitu::job::LoadJobFile(job_path, sets);
  if (!job.ok()) {
    std::fprintf(stderr, "insitu: %s\n", job.status().message().c_str());
    return ExitCodeFor(job.status());
  }
  insitu::job::RunOptions options;
  options.out_dir =
      out_dir.empty() ? "insitu-out/" + std::filesystem::path(job_path).stem().string() : out_dir;
  options.cancel = &g_cancel;
  options.ask_person = AskAtConsole;
  auto report = insitu::job::RunJob(*job, options);
  if (!report.ok()) {
    std::fprintf(stderr, "insitu: %s\n", report.status().message().c_str());
    return ExitCodeFor(report.status());
  }
  const std::filesystem::path dir(options.out_dir);
  std::printf("report: %s\n", (dir / "report.json").c_str());
  for (const auto& [name, path] : report->artifacts) {
    std::printf("%s: %s\n", name.c_str(), (dir / path).c_str());
  }
  for (const std::string& w : report->warnings) std::printf("warning: %s\n", w.c_str());
  return 0;
}

int Diagnose(const std::string& csv, const std::string& out_dir, const std::string& reading) {
  const std::string out = out_dir.empty()
                              ? "insitu-out/diagnose-" + std::filesystem::path(csv).stem().string()
                              : out_dir;
  auto d = insitu::job::RunDiagnose(csv, out, {}, reading);
  if (!d.ok()) {
    std::fprintf(stderr, "insitu: %s\n", d.status().message().c_str());
    return ExitCodeFor(d.status());
  }
  std::printf("%s\n", d->Summary().c_str());
  const std::filesystem::path dir(out);
  std::printf("report: %s\nresiduals: %s\nextension: %s\n", (dir / "report.json").c_str(),
              (dir / "residuals.png").c_str(), (dir / "extension.yaml").c_str());
  return 0;
}

// What a drawing will mark, before anything moves: extents, units, what was drawn and
// skipped, the closed areas, and preview.png with the hatch at scale.
int PatternInspect(const std::string& file, const std::string& out_dir,
                   insitu::job::PatternInspectOptions options) {
  const std::filesystem::path dir =
      out_dir.empty() ? "insitu-out/pattern-" + std::filesystem::path(file).stem().string()
                      : out_dir;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    std::fprintf(stderr, "insitu: cannot create %s: %s\n", dir.c_str(), ec.message().c_str());
    return 1;
  }
  options.preview_path = (dir / "preview.png").string();
  auto in = insitu::job::InspectPattern(file, options);
  if (!in.ok()) {
    std::fprintf(stderr, "insitu: %s\n", in.status().message().c_str());
    return ExitCodeFor(in.status());
  }
  std::printf("%s", insitu::job::FormatInspection(file, *in).c_str());
  return 0;
}

// An LMC board's .cor file as insitu's field correction table (head.correction), and back.
// Import reads the file the way the two-mirror head model explains best (fit/cor_physics.h),
// unless `reading_code` forces one; export writes the table as --reading says, else as the
// CSV's "# reading:" comment (written by import) says, else in the documented convention for
// the board (swap_xy: which word drives the first mirror).
// `insitu lmc decode FILE`: a USB capture of an LMC board's traffic, one command a line.
int LmcDecode(const std::string& path) {
  auto text = insitu::hw::lmc::DecodeCaptureFile(path);
  if (!text.ok()) {
    std::fprintf(stderr, "insitu: %s\n", text.status().message().c_str());
    return ExitCodeFor(text.status());
  }
  std::fputs(text->c_str(), stdout);
  return 0;
}

int CorImport(const std::string& cor_path, const std::string& out,
              const std::string& reading_code) {
  namespace lmc = insitu::hw::lmc;
  auto read = insitu::job::ReadCorByPhysics(cor_path, reading_code);
  if (!read.ok()) {
    std::fprintf(stderr, "insitu: %s\n", read.status().message().c_str());
    return read.status().code() == insitu::StatusCode::kInvalidArgument ? 2
                                                                         : ExitCodeFor(read.status());
  }
  const std::vector<lmc::CorReading>& readings = read->readings;
  const insitu::fit::CorReadingChoice* choice = &read->choice;
  const lmc::CorFile* cor = &read->cor;
  const int used = read->used;
  const int forced = read->forced ? used : -1;
  const auto pct = [&](int k) { return 100.0 * choice->fits[k].explained; };
  const char* what = read->summary.c_str();
  const insitu::Status saved =
      insitu::WriteFileAtomically(out, "# insitu cor import " + cor_path + ": " + what + "\n" +
                                           lmc::ToCorrectionCsv(*cor, readings[used]));
  if (!saved.ok()) {
    std::fprintf(stderr, "insitu: %s\n", saved.message().c_str());
    return 1;
  }
  std::printf("%s: 65 x 65 nodes, lens %.2f mm; %s -> %s\n", cor_path.c_str(), cor->lens_mm(), what,
              out.c_str());
  std::vector<int> order(readings.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return pct(a) > pct(b); });
  for (int k : order) {
    std::printf("  %6.1f %% (beyond affine %6.1f %%)  %s (--reading %s)\n", pct(k),
                100.0 * choice->fits[k].explained_nonlinear, readings[k].Name().c_str(),
                readings[k].Code().c_str());
  }
  if (!read->evidence.empty()) std::printf("%s\n", read->evidence.c_str());
  if (!read->wiring.empty()) std::printf("%s\n", read->wiring.c_str());
  if (forced < 0 && !choice->warning.empty()) {
    std::printf("warning: %s\n", choice->warning.c_str());
  }
  if (forced >= 0 && choice->chosen >= 0 && forced != choice->chosen) {
    std::printf("warning: the evidence reads the table as %s (%.1f %%)\n",
                readings[choice->chosen].Name().c_str(), pct(choice->chosen));
  }
  return 0;
}

// The board's axes for an export: given on the command line (they win over a CSV's reading
// comment), else none.
struct ExportAxes {
  bool swap_xy = false, flip_x = false, flip_y = false;
  bool Given() const { return swap_xy || flip_x || flip_y; }
};

int CorExport(const std::string& table_path, double lens_mm, const std::string& format,
              const std::string& reading_code, const ExportAxes& axes, const std::string& out) {
  namespace lmc = insitu::hw::lmc;
  auto table = insitu::pattern::CorrectionTable::Load(table_path);
  if (!table.ok()) {
    std::fprintf(stderr, "insitu: %s\n", table.status().message().c_str());
    return ExitCodeFor(table.status());
  }
  const lmc::CorFormat cor_format =
      format == "lmc1" ? lmc::CorFormat::kLmc1 : lmc::CorFormat::kJcz2;
  std::optional<lmc::CorReading> reading;
  if (!reading_code.empty()) {
    if (axes.Given()) {
      std::fprintf(stderr,
                   "insitu: --reading and the board's axes (--swap-xy, --flip-x, "
                   "--flip-y) say the same thing twice: give one\n");
      return 2;
    }
    auto r = lmc::ParseCorReading(reading_code);
    if (!r.ok()) {
      std::fprintf(stderr, "insitu: --reading: %s\n", r.status().message().c_str());
      return 2;
    }
    reading = *r;
  } else if (!axes.Given()) {
    std::ifstream f(table_path);
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    auto r = lmc::CorReadingOfCsv(text, table_path);
    if (!r.ok()) {
      std::fprintf(stderr, "insitu: %s\n", r.status().message().c_str());
      return 2;
    }
    if (r->has_value()) reading = **r;
  }
  lmc::CorFile cor;
  std::string stored;
  if (reading) {
    cor = lmc::FromCorrection([&](double x, double y) { return table->OffsetAt(x, y); }, lens_mm,
                              cor_format, *reading);
    stored = reading->Name();
  } else {
    // The documented convention, in the words of a board with these axes.
    lmc::BoardOptions board;
    board.lens_mm = lens_mm;
    board.swap_xy = axes.swap_xy;
    board.flip_x = axes.flip_x;
    board.flip_y = axes.flip_y;
    cor = lmc::BoardTableFromDrive(
        [&](const Eigen::Vector2d& p) {
          return Eigen::Vector2d(p + table->OffsetAt(p.x(), p.y()));
        },
        board, cor_format);
    stored = std::string("the documented convention for a board with swap_xy ") +
             (axes.swap_xy ? "true" : "false") + ", flip_x " + (axes.flip_x ? "true" : "false") +
             ", flip_y " + (axes.flip_y ? "true" : "false");
  }
  const insitu::Status saved = lmc::WriteCor(out, cor);
  if (!saved.ok()) {
    std::fprintf(stderr, "insitu: %s\n", saved.message().c_str());
    return ExitCodeFor(saved);
  }
  std::printf("%s (%d x %d nodes) -> %s, %s format, lens %.2f mm, stored as %s\n",
              table_path.c_str(), table->nodes_x(), table->nodes_y(), out.c_str(), format.c_str(),
              lens_mm, stored.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"insitu: measure-then-mark with a 3D galvo scan head and a side camera"};
  app.set_version_flag("--version", std::string("insitu ") + INSITU_VERSION);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error or off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
  app.require_subcommand(1);
  app.footer(
      "Exit codes: 0 done; 1 device or job failure (the report says what); 2 bad input (the "
      "command line, a job file or --set, a calibration, pattern or data file); 130 "
      "interrupted (SIGINT or SIGTERM: a scan stops between lines, a marking list is aborted "
      "by the head within one clock tick, the laser off).");

  CLI::App* run = app.add_subcommand("run", "run a job file (YAML) on the machine it names");
  std::string job_path, out_dir;
  std::vector<std::string> sets;
  run->add_option("job", job_path, "job file")->required();
  run->add_option("--out", out_dir, "output folder (default insitu-out/<job name>)");
  run->add_option("--set", sets, "override a job key: dotted.key=value (repeatable)")
      ->take_all()
      ->allow_extra_args(false);

  CLI::App* diagnose = app.add_subcommand("diagnose",
                                          "what the galvo model gets wrong in field data (measured "
                                          "CSV, correction CSV or .cor), and why");
  std::string csv_path, diag_out;
  diagnose
      ->add_option("data", csv_path,
                   "field data CSV (x_cmd_mm, y_cmd_mm, x_meas_mm, y_meas_mm), a correction table "
                   "CSV (x_mm, y_mm, dx_mm, dy_mm) or an EzCad .cor file")
      ->required();
  diagnose->add_option("--out", diag_out, "output folder (default insitu-out/diagnose-<name>)");
  std::string diag_reading;
  diagnose->add_option("--reading", diag_reading,
                       "a .cor file: read it as this (e.g. dx-dy,y-major,--) instead of as the "
                       "head model and the documented convention decide");

  CLI::App* cor = app.add_subcommand("cor", "EzCad .cor correction files of LMC galvo boards");
  cor->require_subcommand(1);
  CLI::App* cor_import = cor->add_subcommand("import", "a .cor file as insitu's field table (CSV)");
  std::string cor_in, cor_out, import_reading, export_reading;
  cor_import->add_option("file", cor_in, ".cor file (JCZ_COR_2_1 or LMC1COR_1.0)")->required();
  cor_import->add_option("--out", cor_out, "field correction CSV to write")->required();
  cor_import->add_option("--reading", import_reading,
                         "read the file as this (e.g. dx-dy,y-major,--) instead of as the head "
                         "model and the documented convention decide");
  CLI::App* cor_export = cor->add_subcommand("export", "insitu's field table (CSV) as a .cor file");
  std::string table_in, cor_file, cor_format = "jcz";
  double lens_mm = 0.0;
  cor_export->add_option("table", table_in, "field correction CSV (head.correction)")->required();
  cor_export->add_option("--lens", lens_mm, "the board's lens field, mm")
      ->required()
      ->check(CLI::Range(1.0, 2000.0));
  cor_export->add_option("--format", cor_format, "jcz (JCZ_COR_2_1) or lmc1 (LMC1COR_1.0)")
      ->check(CLI::IsMember({"jcz", "lmc1"}));
  cor_export->add_option("--reading", export_reading,
                         "store the table as this (e.g. dx-dy,y-major,--); default: the CSV's "
                         "'# reading:' comment (cor import writes it), else the documented "
                         "convention in the words of a board with --swap-xy, --flip-x, --flip-y");
  ExportAxes export_axes;
  cor_export->add_flag("--swap-xy", export_axes.swap_xy,
                       "the board's lmc.swap_xy: its second position word drives galvo x, the "
                       "first mirror (the table is stored in the board's own words)");
  cor_export->add_flag("--flip-x", export_axes.flip_x, "the board's lmc.flip_x");
  cor_export->add_flag("--flip-y", export_axes.flip_y, "the board's lmc.flip_y");
  cor_export->add_option("--out", cor_file, ".cor file to write")->required();

  CLI::App* lmc = app.add_subcommand("lmc", "LMC galvo boards' USB traffic");
  lmc->require_subcommand(1);
  CLI::App* lmc_decode = lmc->add_subcommand(
      "decode",
      "a USB capture of an LMC board's traffic (usbmon text, pcap or pcapng; Linux "
      "usbmon or Windows USBPcap), one command a line as in galvo_list.txt");
  std::string capture_path;
  lmc_decode->add_option("file", capture_path, "the capture")->required();

  CLI::App* pattern = app.add_subcommand("pattern", "vector drawings (SVG, DXF, HPGL) to mark");
  pattern->require_subcommand(1);
  CLI::App* inspect = pattern->add_subcommand(
      "inspect", "what a drawing will mark: extents, units, entities drawn and skipped, closed "
                 "areas, and preview.png with the hatch at scale");
  std::string inspect_file, inspect_out;
  insitu::job::PatternInspectOptions inspect_options;
  inspect->add_option("file", inspect_file, ".svg, .dxf or .plt/.hpgl drawing")->required();
  inspect->add_option("--out", inspect_out,
                      "folder for preview.png (default insitu-out/pattern-<name>)");
  inspect->add_option("--scale", inspect_options.scale, "as the mark job's placement.scale")
      ->check(CLI::PositiveNumber);
  inspect->add_option("--hatch-spacing", inspect_options.hatch_spacing_mm,
                      "mm on the part, as the mark job's hatch.spacing_mm (default 0.04)")
      ->check(CLI::PositiveNumber);
  inspect->add_option("--hatch-angles", inspect_options.hatch_angles_deg,
                      "degrees, as the mark job's hatch.angles_deg (default 0)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version print and exit 0; a command line CLI11 refuses is bad input.
    return app.exit(e) == 0 ? 0 : 2;
  }
  insitu::SetLogLevel(log_level);
  if (run->parsed()) {
    // Before the job file loads: an interrupt then stops the job at its first step. (The other
    // commands keep the default: an interrupt ends them at once, with 130 from the shell.)
    std::signal(SIGINT, OnSignal);
    std::signal(SIGTERM, OnSignal);
    return Run(job_path, out_dir, sets);
  }
  if (diagnose->parsed()) return Diagnose(csv_path, diag_out, diag_reading);
  if (inspect->parsed()) return PatternInspect(inspect_file, inspect_out, inspect_options);
  if (cor_import->parsed()) return CorImport(cor_in, cor_out, import_reading);
  if (lmc_decode->parsed()) return LmcDecode(capture_path);
  if (cor_export->parsed()) {
    return CorExport(table_in, lens_mm, cor_format, export_reading, export_axes, cor_file);
  }
  return 2;
}
