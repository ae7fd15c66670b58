// An LMC board's .cor correction file read the way the physics explains it
// (fit/cor_physics.h), for `insitu cor import` and for `insitu diagnose FILE.cor`; and any
// field correction table as galvo field data for the diagnosis.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/fit/cor_physics.h"
#include "insitu/fit/field_data.h"
#include "insitu/hw/lmc_cor.h"

namespace insitu::job {

struct CorByPhysics {
  hw::lmc::CorFile cor;
  std::vector<hw::lmc::CorReading> readings;  // all 16, hw::lmc::AllCorReadings() order
  fit::CorReadingChoice choice;               // the head model's fit of each
  int used = -1;                              // the reading used: chosen, or forced
  bool forced = false;                        // by `reading_code`
  // "read as <reading>: the two-mirror head model explains X % (next best <reading> Y %)".
  std::string summary;
  // "decided by <the choice's evidence>" (empty when forced).
  std::string evidence;
  // For a reading in the documented convention: which board word drives the first mirror and
  // the lmc.swap_xy that gives insitu's galvo frame on that board (empty otherwise).
  std::string wiring;

  // The table in the reading used: node positions and offsets (galvo frame, mm).
  std::vector<Eigen::Vector2d> Nodes() const;
  std::vector<Eigen::Vector2d> Offsets() const;
};

// Reads `path` and fits the head to every reading; the reading used is the one the physics
// and the documented convention decide (fit::ChooseCorReading). `reading_code`
// (hw::lmc::ParseCorReading) forces one. Errors: ReadCor's; invalid_argument for a bad reading
// code, and when nothing decides the reading (the message names the candidates' codes for
// --reading); ChooseCorReading's.
Result<CorByPhysics> ReadCorByPhysics(const std::string& path,
                                      const std::string& reading_code = "");

// A correction table as galvo field data: at node p the board adds o(p) to the command, and the
// spot lands on p. So the command is p + o(p) and the measured position p: the head without
// the table, as the diagnosis sees a measured field. Errors: invalid_argument when the sizes
// differ or a value is not finite.
Result<fit::FieldData> FieldDataFromCorrection(const std::vector<Eigen::Vector2d>& node_mm,
                                               const std::vector<Eigen::Vector2d>& offset_mm,
                                               const std::string& origin);

}  // namespace insitu::job
