#include "insitu/job/cor_reading.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace insitu::job {

std::vector<Eigen::Vector2d> CorByPhysics::Nodes() const {
  std::vector<Eigen::Vector2d> out;
  for (int i = 0; i < 65; ++i) {
    for (int j = 0; j < 65; ++j) out.push_back(cor.NodeMm(i, j));
  }
  return out;
}

std::vector<Eigen::Vector2d> CorByPhysics::Offsets() const {
  std::vector<Eigen::Vector2d> out;
  for (int i = 0; i < 65; ++i) {
    for (int j = 0; j < 65; ++j) out.push_back(cor.OffsetMm(i, j, readings[used]));
  }
  return out;
}

Result<CorByPhysics> ReadCorByPhysics(const std::string& path, const std::string& reading_code) {
  namespace lmc = hw::lmc;
  CorByPhysics r;
  INSITU_ASSIGN_OR_RETURN(r.cor, lmc::ReadCor(path));
  r.readings = lmc::AllCorReadings();
  int forced = -1;
  if (!reading_code.empty()) {
    auto code = lmc::ParseCorReading(reading_code);
    if (!code.ok()) return code.status().Prefixed("reading");
    forced = static_cast<int>(std::find(r.readings.begin(), r.readings.end(), *code) -
                              r.readings.begin());
  }
  std::vector<fit::CorReadingCandidate> candidates;
  for (const lmc::CorReading& reading : r.readings) {
    fit::CorReadingCandidate c;
    c.name = reading.Name();
    c.documented = lmc::IsDocumentedReading(reading);
    for (int i = 0; i < 65; ++i) {
      for (int j = 0; j < 65; ++j) {
        c.node_mm.push_back(r.cor.NodeMm(i, j));
        c.offset_mm.push_back(r.cor.OffsetMm(i, j, reading));
      }
    }
    candidates.push_back(std::move(c));
  }
  fit::CorPhysicsOptions options;
  options.lens_mm = r.cor.lens_mm();
  options.quantum_mm = r.cor.format == lmc::CorFormat::kJcz2 ? 1.0 / r.cor.scale : 0.0;
  auto choice = fit::ChooseCorReading(candidates, options);
  if (!choice.ok()) return choice.status().Prefixed(path);
  r.choice = std::move(*choice);
  r.forced = forced >= 0;
  if (!r.forced && r.choice.chosen < 0) {
    // Nothing decides: refuse, naming what the user can choose from.
    std::string codes;
    const std::vector<int>& named =
        r.choice.tied.empty() ? std::vector<int>{r.choice.best} : r.choice.tied;
    for (int k : named) codes += (codes.empty() ? "" : " or ") + r.readings[k].Code();
    return InvalidArgument(path + ": the reading of the table cannot be decided: " +
                           r.choice.evidence + "; name it with --reading (" + codes + ")");
  }
  r.used = r.forced ? forced : r.choice.chosen;
  const auto pct = [&](int k) { return 100.0 * r.choice.fits[k].explained; };
  int next = -1;  // the best reading other than the one used
  for (int k = 0; k < static_cast<int>(r.readings.size()); ++k) {
    if (k != r.used && (next < 0 || pct(k) > pct(next))) next = k;
  }
  char what[512];
  std::snprintf(what, sizeof what,
                "read as %s%s: the two-mirror head model explains %.1f %% (%s: %s %.1f %%)",
                r.readings[r.used].Name().c_str(), r.forced ? " (--reading)" : "", pct(r.used),
                r.used == r.choice.best ? "next best" : "best", r.readings[next].Name().c_str(),
                pct(next));
  r.summary = what;
  if (!r.forced) r.evidence = "why this reading: " + r.choice.evidence;
  // A table of zeros says nothing of the wiring.
  if (lmc::IsDocumentedReading(r.readings[r.used]) && r.choice.fits[r.used].table_rms_mm > 0) {
    r.wiring = lmc::FirstMirrorOnWord2(r.readings[r.used])
                   ? "the head's first mirror is on the board's second axis word: insitu's "
                     "galvo x (the first mirror) needs lmc.swap_xy: true on this board"
                   : "the head's first mirror is on the board's first axis word: insitu's "
                     "galvo x (the first mirror) needs lmc.swap_xy: false on this board";
  }
  return r;
}

Result<fit::FieldData> FieldDataFromCorrection(const std::vector<Eigen::Vector2d>& node_mm,
                                               const std::vector<Eigen::Vector2d>& offset_mm,
                                               const std::string& origin) {
  if (node_mm.size() != offset_mm.size()) {
    return InvalidArgument(origin + ": " + std::to_string(node_mm.size()) + " nodes but " +
                           std::to_string(offset_mm.size()) + " offsets");
  }
  fit::FieldData d;
  d.origin = origin;
  for (size_t k = 0; k < node_mm.size(); ++k) {
    if (!node_mm[k].allFinite() || !offset_mm[k].allFinite()) {
      return InvalidArgument(origin + ": node " + std::to_string(k) + " is not finite");
    }
    fit::FieldPoint p;
    p.cmd = node_mm[k] + offset_mm[k];
    p.meas = node_mm[k];
    p.line = static_cast<int>(k) + 1;
    d.points.push_back(p);
  }
  return d;
}

}  // namespace insitu::job
