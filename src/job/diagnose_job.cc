#include "insitu/job/diagnose_job.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "insitu/core/file.h"
#include "insitu/fit/extension.h"
#include "insitu/fit/field_data.h"
#include "insitu/job/cor_reading.h"
#include "insitu/pattern/correction_table.h"
#include "insitu/vision/canvas.h"

namespace insitu::job {
namespace {

constexpr int kArrow = 0xC83C28;  // residual arrows and their scale bar

// One panel of the quiver plot: commanded points, residual arrows scaled so the longest is a
// tenth of the field's span, the scale written under it.
// A rectangle of pixels [x, x + width) x [y, y + height).
struct Box {
  int x, y, width, height;
};

void DrawPanel(vision::Canvas& img, const Box& area, const fit::FieldData& data,
               const std::vector<Eigen::Vector2d>& residual, const std::string& title) {
  img.Rectangle(area.x, area.y, area.width, area.height, {.rgb = 0xC8C8C8});
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& p : data.points) {
    lo = lo.cwiseMin(p.cmd);
    hi = hi.cwiseMax(p.cmd);
  }
  const double span = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-6});
  const int margin = 60;
  const double px_per_mm = (std::min(area.width, area.height) - 2.0 * margin) / span;
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  const auto to_px = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(area.x + 0.5 * area.width + (p.x() - mid.x()) * px_per_mm,
                           area.y + 0.5 * area.height - (p.y() - mid.y()) * px_per_mm);  // y up
  };
  double longest = 0.0;
  for (const auto& r : residual) longest = std::max(longest, r.norm());
  // Arrow magnification: the longest arrow a tenth of the span (a round number).
  double gain = longest > 0 ? 0.1 * span / longest : 1.0;
  const double decade = std::pow(10.0, std::floor(std::log10(gain)));
  for (double f : {5.0, 2.0, 1.0}) {
    if (gain >= f * decade) {
      gain = f * decade;
      break;
    }
  }
  for (size_t i = 0; i < data.points.size(); ++i) {
    const Eigen::Vector2d a = to_px(data.points[i].cmd);
    const Eigen::Vector2d b = to_px(data.points[i].cmd + gain * residual[i]);
    img.Circle(a, 2, {.rgb = 0x5A5A5A, .thickness = vision::kFill, .smooth = true});
    img.Arrow(a, b, {.rgb = kArrow, .smooth = true}, 0.25);
  }
  double rms = 0.0;
  for (const auto& r : residual) rms += r.squaredNorm();
  rms = std::sqrt(rms / std::max<size_t>(1, residual.size()));
  char buf[200];
  // A long list of causes: the title shrinks to the panel's width.
  const double width = vision::Canvas::MeasureText(title, 0.6).width;
  const double font = 0.6 * std::min(1.0, (area.width - 20) / std::max(1.0, width));
  const vision::Pen text{.rgb = 0x000000, .smooth = true};
  img.Text(title, Eigen::Vector2d(area.x + 10, area.y + 24), font, text);
  std::snprintf(buf, sizeof buf, "rms %.4f mm, longest %.4f mm; arrows x %g", rms, longest, gain);
  img.Text(buf, Eigen::Vector2d(area.x + 10, area.y + area.height - 14), 0.5, text);
  // A scale bar: what 0.01 mm (or the longest residual's decade) looks like at that gain.
  const double bar_mm = std::pow(10.0, std::floor(std::log10(std::max(longest, 1e-9))));
  const Eigen::Vector2d s0(area.x + area.width - 80 - bar_mm * gain * px_per_mm, area.y + 40);
  img.Line(s0, s0 + Eigen::Vector2d(bar_mm * gain * px_per_mm, 0), {.rgb = kArrow, .thickness = 2});
  std::snprintf(buf, sizeof buf, "%g mm", bar_mm);
  img.Text(buf, s0 + Eigen::Vector2d(0, 18), 0.45, {.rgb = kArrow, .smooth = true});
}

}  // namespace

Result<fit::FieldData> LoadDiagnoseData(const std::string& path, std::string* source,
                                        const std::string& cor_reading) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".cor" || ext == ".COR") {
    INSITU_ASSIGN_OR_RETURN(CorByPhysics cor, ReadCorByPhysics(path, cor_reading));
    *source =
        "EzCad .cor table, " + cor.summary + (cor.evidence.empty() ? "" : "; ") + cor.evidence;
    return FieldDataFromCorrection(cor.Nodes(), cor.Offsets(), path);
  }
  std::ifstream in(path);
  if (!in) return NotFound("cannot read " + path);
  std::stringstream text;
  text << in.rdbuf();
  // The header row decides: measured field data (x_cmd_mm ...) or a correction table
  // (x_mm, y_mm, dx_mm, dy_mm: what `insitu cor import` and field_calibration write).
  std::istringstream lines(text.str());
  std::string line;
  while (std::getline(lines, line)) {
    if (!line.empty() && line[0] != '#' && line.find_first_not_of(" \t\r") != std::string::npos)
      break;
  }
  if (line.find("x_cmd_mm") == std::string::npos && line.find("dx_mm") != std::string::npos) {
    INSITU_ASSIGN_OR_RETURN(pattern::CorrectionTable table,
                            pattern::CorrectionTable::Parse(text.str(), path));
    std::vector<Eigen::Vector2d> nodes;
    const optics::GridTable& g = table.table();
    for (double y : g.ys()) {
      for (double x : g.xs()) nodes.emplace_back(x, y);
    }
    *source =
        "correction table (x_mm, y_mm, dx_mm, dy_mm): the head without it, commanded p + "
        "offset, lands on p";
    return FieldDataFromCorrection(nodes, g.values(), path);
  }
  *source = "measured field data";
  return fit::ParseFieldCsv(text.str(), path);
}

Result<fit::Diagnosis> RunDiagnose(const std::string& csv_path, const std::string& out_dir,
                                   const fit::DiagnoseOptions& options,
                                   const std::string& cor_reading) {
  std::string source;
  INSITU_ASSIGN_OR_RETURN(fit::FieldData data, LoadDiagnoseData(csv_path, &source, cor_reading));
  INSITU_ASSIGN_OR_RETURN(fit::Diagnosis d, fit::Diagnose(data, options));
  d.notes.insert(d.notes.begin(), "source: " + source);
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return NotFound("cannot create output folder " + out_dir);
  const std::filesystem::path dir(out_dir);
  // Atomic: a reader never sees half a report.
  INSITU_RETURN_IF_ERROR(WriteFileAtomically((dir / "report.json").string(), d.ToJson() + "\n"));
  {
    // The extended model, for the simulator (world scan_head.field_effects) and the galvo list
    // (mark job head.model_extension).
    INSITU_ASSIGN_OR_RETURN(fit::ModelExtension ext, fit::ModelExtension::FromDiagnosis(d));
    INSITU_RETURN_IF_ERROR(fit::SaveExtension(ext, csv_path, (dir / "extension.yaml").string()));
  }
  vision::Canvas img(1240, 620);
  // A table of moves: the nominal model is the command less the offset every move shares.
  DrawPanel(img, Box{10, 10, 600, 600}, data, d.residual_nominal,
            data.reference >= 0 ? "measured - nominal (command + the moves' common offset)"
                                : "measured - commanded (nominal model)");
  std::string after = "measured - extended model";
  if (!d.cause.empty()) {
    after += " (";
    for (size_t k = 0; k < d.cause.size(); ++k) after += (k ? " + " : "") + d.cause[k];
    after += ")";
  }
  DrawPanel(img, Box{630, 10, 600, 600}, data, d.residual_extended, after);
  INSITU_RETURN_IF_ERROR(img.WritePng((dir / "residuals.png").string()));
  return d;
}

}  // namespace insitu::job
