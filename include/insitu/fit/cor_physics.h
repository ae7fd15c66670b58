// How much of a galvo board's field correction table the two-mirror head explains, and which
// way of reading a stored table it explains best: a board's correction file does not say in
// which order its nodes and offset pairs are stored, nor their signs (docs/hardware.md, ".cor
// files"), so insitu lets the physics decide.
//
// The model: a board without a correction table drives the mirrors linearly, optical angles
//   a = g_x c_x / f + a0,   b = g_y c_y / f + b0
// for a command c (galvo frame, mm), through the project's head (optics/scan_head.h,
// TraceChiefRay: the X mirror first, the f-theta objective r = f theta (1 + c3 theta^2 +
// c5 theta^4), the mirrors' axes tilted), and the field turned by phi:
//   H(c) = R(phi) trace(a, b),   focal plane z = 0.
// The gains g_x, g_y are the board's scale error per axis (1: a small command lands where it
// asks), f sets the size of the two-mirror distortion (X pincushion, Y barrel: seed 003
// sec. 1.2) and cannot change its sign, c3 and c5 are the lens's radial distortion, a0 and b0
// the mirrors' zero offsets, and both mirrors' axis tilts are fitted: with the angles linear
// in the command the common part of the tilts is not quite a turn of the field, and a Y tilt
// of 0.8 mrad left 3 um that phi and the X tilt could not take (tests/fit/cor_physics_test.cc).
// The mirror separation moves the chief ray's pupil, not its focal point: it is not in H.
//
// A correction table holds, at node p, the offset the board adds to a command at p so that
// the spot lands on p: physically H^-1(p) - p. The fit minimises |H(p + o(p)) - p| over the
// nodes (Levenberg-Marquardt, Ceres, a few starting focal lengths); what it reports is in the
// table's own terms, the offset residual r(p) = (H^-1(p) - p) - o(p):
//   explained = 1 - rms |r| / rms |o|,
// with rms |o| about zero (the table's offsets as they are: a constant offset is part of the
// table and the zero offsets explain it). 1: the head explains the table; ~0: it explains
// nothing of it (a table of noise); below 0 when the fitted head is further from the table
// than no correction at all.
//
// Readings: the same stored numbers read in different conventions are different candidate
// tables in the galvo frame (hw/lmc_cor.h builds them). ChooseCorReading fits each and decides:
// - nothing, when the best reading explains less than `min_explained` of the table or less
//   than `min_explained_nonlinear` of its part beyond an affine map (an affine table fits any
//   reading whose flips the gains and the turn absorb: only the distortion can show a
//   reading);
// - the physics alone, when every other reading is more than `ambiguous_margin` below the
//   best;
// - else, when several readings are within the margin of the best (they differ by a symmetry
//   the table shows only weakly, below), the format's documented convention among them: if
//   exactly one of them is `documented`, it is chosen, and the choice says both pieces of
//   evidence;
// - else nothing decides: `chosen` is -1 and the warning names the candidates. Never a
//   default the table contradicts.
// A table whose offsets are all zero is the same in every reading: the documented one.
//
// What the physics can tell apart. The head's distortion has a fixed shape and sign: the
// field angle of the X mirror (first) is seen by the Y mirror, so X bows as a pincushion and Y
// as a barrel (f > 0 sets the size, never the sign), and c3, c5 add only radial terms. So:
// - a sign flip of one component, or of both, turns the pincushion into a barrel: told apart;
// - swapping the pair, or the node order alone, puts the x correction's odd-in-x shape on y:
//   told apart;
// - node order and pair order swapped together is the same table for a head whose FIRST
//   mirror is on y: the model fixes the X mirror first (insitu's galvo frame), so these are
//   told apart only through that convention; a board whose x axis drives the second mirror
//   comes out as the transposed reading (set the board's swap_xy to match);
// - node order, pair order and both signs changed together (the table transposed and
//   negated) is told apart only weakly: the transposition swaps which mirror is first, the
//   negation turns the pincushion into a barrel, and together they come back to a first-X
//   pincushion but with the lens's radial term of the other sign; what is left is a sixth of
//   the two-mirror term, which a table made by a tool other than the exact physics (EzCad's
//   tables are built quadrant by quadrant) can hide. Real tables (four public EzCad tables)
//   put such twins within 1-4 points of each other; the documented convention decides them;
// - a table that holds only a linear field (scale, rotation, offset) fits every reading whose
//   sign flips the gains absorb: not told apart by the physics;
// - a radially symmetric table (lens distortion only) is told apart from its transposed and
//   its negated reading only by the two-mirror term: weakly, for a long focal length.
//
// Frames: galvo frame, mm, origin on the optical axis (the table's centre node).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::fit {

// The fitted linear-drive head.
struct LinearDriveHead {
  double focal_length_mm = 0.0;
  double gain_x = 1.0, gain_y = 1.0;  // a = gain_x c_x / f: 1 when a small command lands right
  double ftheta_c3 = 0.0, ftheta_c5 = 0.0;
  double x_axis_tilt_mrad = 0.0, y_axis_tilt_mrad = 0.0;
  double x_zero_offset_mrad = 0.0, y_zero_offset_mrad = 0.0;  // optical angles
  double rotation_mrad = 0.0;                                 // of the field, counterclockwise

  // Where a command lands (galvo frame, mm, z = 0).
  Eigen::Vector2d Land(const Eigen::Vector2d& command_mm) const;
  // The correction this head needs at p: H^-1(p) - p (Newton, to 1e-9 mm). False if it does
  // not converge (p beyond the head's field).
  bool Offset(const Eigen::Vector2d& p_mm, Eigen::Vector2d* offset_mm) const;
};

struct CorPhysicsOptions {
  // The field the table spans (its width, mm): bounds and starts the focal length, which is
  // kept within half field angles of 0.7 rad (widest f-theta lenses ~0.45) down to 0.005 rad
  // (where the two-mirror distortion vanishes: the head explains nothing but a scale).
  double lens_mm = 110.0;
  bool fit_gains = true;
  bool fit_ftheta_distortion = true;  // c3, c5
  bool fit_axis_tilt = true;
  bool fit_zero_offsets = true;
  bool fit_rotation = true;
  int max_iterations = 100;
  // Every `stride`-th node along each axis in the fit (1: all); the explained fraction is
  // always over all nodes. 4: 17 x 17 of a 65 x 65 table, 16 readings in ~1 s, explained
  // fractions within 1 point of stride 2's (tests/fit/cor_physics_test.cc's table).
  int stride = 4;
  // ChooseCorReading decides nothing when the best explains less than this of the table, and
  // by the physics alone when every other reading is more than `ambiguous_margin` below the
  // best (fractions, not %).
  double min_explained = 0.5;
  // Of the part beyond an affine map. Real EzCad tables: 63 % and 79 % in the reading chosen
  // (EzCad builds its tables quadrant by quadrant, which no head does); a table of noise ~0.
  double min_explained_nonlinear = 0.3;
  // The table's storage step (a JCZ file's whole units: lens / 65536), mm; 0: exact. What is
  // left beyond an affine map below half of it is rounding, not distortion.
  double quantum_mm = 0.0;
  double ambiguous_margin = 0.05;

  Status Validate() const;
};

struct CorTableFit {
  LinearDriveHead head;
  double explained = 0.0;        // 1 - rms |r| / rms |o| (fraction)
  double table_rms_mm = 0.0;     // rms |o|
  double residual_rms_mm = 0.0;  // rms |r|
  double residual_max_mm = 0.0;  // max |r|
  // The table less its least-squares affine part (what no gain, shear, turn or offset
  // explains, and so what tells readings apart), and 1 - rms |r| / that.
  double nonlinear_rms_mm = 0.0;
  double explained_nonlinear = 0.0;
  std::string summary;  // Ceres's brief report of the best start
};

// Fits the linear-drive head to a correction table: node_mm[k] (galvo frame) and the offset
// offset_mm[k] the table holds there. Errors: invalid_argument (sizes differ, fewer than 12
// nodes, a non-finite value, bad options), failed_precondition (no start gave a usable
// solution). A table whose offsets are all zero is explained 0 (nothing to explain), not an
// error.
Result<CorTableFit> ExplainCorrectionTable(const std::vector<Eigen::Vector2d>& node_mm,
                                           const std::vector<Eigen::Vector2d>& offset_mm,
                                           const CorPhysicsOptions& options);

// One reading of a stored table: its name (for reports), whether it is the convention the
// file format is documented in, and the table it makes.
struct CorReadingCandidate {
  std::string name;
  bool documented = false;
  std::vector<Eigen::Vector2d> node_mm;
  std::vector<Eigen::Vector2d> offset_mm;
};

struct CorReadingChoice {
  std::vector<CorTableFit> fits;       // one per candidate, in the candidates' order
  int best = -1;                       // highest explained
  int runner_up = -1;                  // the next (-1 with one candidate)
  std::vector<int> tied;               // within ambiguous_margin of the best, best first
  int chosen = -1;                     // -1: nothing decides
  bool decided_by_physics = false;     // the physics alone
  bool decided_by_convention = false;  // the documented convention among the tied
  // What decided, in words ("the two-mirror head model: 94.0 % against 71.3 % for the next"),
  // or why nothing did.
  std::string evidence;
  std::string warning;  // nothing decided, or the physics chose an undocumented reading
};

// Fits every candidate and chooses (see the header comment). Errors: invalid_argument (no
// candidates) and ExplainCorrectionTable's.
Result<CorReadingChoice> ChooseCorReading(const std::vector<CorReadingCandidate>& candidates,
                                          const CorPhysicsOptions& options);

}  // namespace insitu::fit
