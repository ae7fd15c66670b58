// The coaxial route of the field calibration (seed 001): where the scan head really points,
// measured by its coaxial camera on a reticle, and seed 001's lookup-table correction of it.
//
// The coaxial camera looks through the same mirrors as the beam, so the centre of its image
// is always where the head points: a mark the head made at command c is seen at the image
// centre whenever the head is back at c, and marks cannot measure the head's field through
// this camera. The reference must be independent of the head (seed 001 sec. 3.1: "the
// galvo scans the calibration grid on the work surface; the camera captures the grid at each
// galvo position"): a chrome-on-glass reticle of "+" crosses at a certified pitch lying on the
// stage. At each command the crosses in view, with their known pitch, place the image centre
// (the head's aim) on the reticle to a small fraction of a micrometre; the same crosses give
// the coaxial camera's scale and rotation on the machine (never from lens data).
//
// Which cross is which (seed 001 sec. 3.3: the error must stay under half the pitch): the
// first frame, at the field centre (sec. 6: start from the plate's centre), names the cross
// nearest the image centre (0, 0); from then on each frame's crosses are numbered from where
// the aims measured so far (a similarity from commands to the reticle) predict this one, and
// the points are visited outward from the centre, so each prediction reaches only a little
// beyond what is known.
//
// Frames. Commands: galvo frame (mm; z the focus height). The reticle frame: mm on the
// reticle, origin at the first frame's cross, axes along its lines. The reticle lies where
// the operator put it: its rotation and translation against the galvo frame are not field
// errors and a rigid fit over the grid nodes removes them (never scale: the reticle's pitch
// is the length standard). Measured aims are reported in the galvo frame through that fit.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/fit/field_models.h"
#include "insitu/hw/machine.h"
#include "insitu/job/runner.h"
#include "insitu/optics/grid_table.h"
#include "insitu/vision/crosses.h"

namespace insitu::job {

struct CoaxialFieldOptions {
  // Grid of commands from -half to +half in x and y (seed 001: a 10 mm field), n per side;
  // the check points are the centres of the grid's cells, measured and never fitted.
  double half_size_mm = 5.0;
  int n = 11;
  bool check_points = true;
  // Height of the reticle's top in the galvo frame (the stage's z plus the reticle's
  // thickness): the head focuses there, where the coaxial image is sharp.
  double surface_z_mm = 0.0;
  // The reticle's certified pitch (the length standard of the measurement).
  double reticle_pitch_mm = 1.0;
  double exposure_us = 2000.0;
  // Jump delay before each frame: the mirrors settle (tracking lag ~0.16 ms; 2 ms leaves
  // exp(-12) of a jump).
  double settle_us = 2000.0;
  // The image as seen from above: u along the reticle's x-ish, v against its y (a camera
  // that looks down through the head). True if the camera's mounting mirrors it.
  bool image_mirrored = false;
  // Least crosses in a frame for its aim to count; at least 3 (two directions and a check).
  int min_crosses = 4;
  // Largest distance between a measured aim and its prediction, as a fraction of the pitch,
  // before the frame's numbering is called ambiguous (seed 001 sec. 3.3: 0.5 is where two
  // crosses become equally likely; a margin below that).
  double max_index_error_fraction = 0.3;
  bool second_pass = true;  // aim at the corrected check points and measure again
  vision::CrossOptions crosses;

  // invalid_argument naming the field.
  Status Validate() const;
};

struct CoaxialFieldResult {
  // Grid nodes and check points: command and measured aim (galvo frame, through the rigid
  // fit of the reticle to the nodes).
  std::vector<fit::GalvoSample> grid;
  std::vector<fit::GalvoSample> check;
  // Second pass: the check points' targets (the original commands) and where the corrected
  // commands landed (galvo frame); empty without it.
  std::vector<fit::GalvoSample> check_after;          // cmd: the target (not the corrected command)
  std::vector<Eigen::Vector3d> check_after_commands;  // what was sent
  Eigen::Isometry2d galvo_from_reticle = Eigen::Isometry2d::Identity();
  // The coaxial camera, calibrated on the reticle: size of a pixel on the surface (median
  // over the frames) and the rotation of its image (u right, v up as seen from above)
  // against the galvo frame, degrees.
  double pixel_um = 0.0;
  double rotation_deg = 0.0;
  double pixel_um_spread = 0.0;  // max - min over the frames
  // Field error at the check points: |measured - commanded| before, |measured - target|
  // after the correction (second pass), um.
  double rms_um_before = 0.0, max_um_before = 0.0;
  double rms_um_after = 0.0, max_um_after = 0.0;
  // Seed 001's lookup table: the offset to add to a command (galvo frame, mm) at every grid
  // node, bilinear between them (the correction that makes the bilinear model of the
  // measured field land where asked).
  optics::GridTable correction;
  // Measurement quality: rms of the crosses about each frame's similarity (um, pooled), the
  // fewest crosses in a frame, frames taken, and the largest distance between a measured aim
  // and its prediction (um): how far the numbering was from seed 001's half-pitch limit.
  double cross_residual_um = 0.0;
  int min_crosses_seen = 0;
  int frames = 0;
  double max_index_error_um = 0.0;
  // The grid's rigid fit: rms of the nodes about it (um), the field error that is not a
  // rigid motion.
  double rigid_rms_um = 0.0;
};

// Measures the head's field through its coaxial camera on a reticle lying under the head,
// fits seed 001's lookup table on the grid, and (second pass) measures the check points again
// through it. The laser never fires: the head moves by lists of one jump each. Cancelled
// through run.cancel between frames; progress as phase "coaxial field", unit "frames".
// `warnings` (may be null) gets what the caller should report but did not stop the run.
// Errors: invalid_argument (options; the grid beyond the head's field), failed_precondition
// (no coaxial camera; no reticle in view at the field centre; too few crosses at a point,
// naming it; numbering ambiguous at a point, naming it; an image mirrored against the galvo
// frame), the devices' errors, cancelled.
Result<CoaxialFieldResult> MeasureCoaxialField(hw::Machine& machine,
                                               const CoaxialFieldOptions& options,
                                               const RunOptions& run,
                                               std::vector<std::string>* warnings);

}  // namespace insitu::job
