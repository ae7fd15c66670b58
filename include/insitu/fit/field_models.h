// Models of a scan head's field, fitted to targets the cameras measured (seed 003 sec. 2.1,
// seed 001): where a command really lands.
//
// Frames. Commands are in the galvo frame (mm, z the focus height). The side camera measures
// targets in the plate frame (the frame of the board that lay on the plate, mm); the board's
// placement is arbitrary, so the plate frame and the galvo frame differ by an unknown rotation
// and translation in the plate plane. That rigid motion is never a field error: the physical
// fit carries it as a nuisance, and `HeadFieldFit::galvo_from_plate` takes measurements into
// the galvo frame, where every other model here works.
//
// Models, side by side (seed 003's table): an n x n bilinear lookup (seed 003 eq. 12-13,
// seed 001 sec. 4.3), seed 003's quadrant curve fit (eq. 10-11, from 9 points), the physical
// head (optics/scan_head.h) fitted with Ceres, and the physical head plus a bilinear table of
// what it leaves (the correction insitu applies: physics first).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "insitu/core/status.h"
#include "insitu/optics/grid_table.h"
#include "insitu/optics/scan_head.h"

namespace insitu::fit {

// One measured target: the command that marked it (galvo frame; z = focus height) and where
// the camera found it (plate frame, mm).
struct TargetSample {
  Eigen::Vector3d cmd = Eigen::Vector3d::Zero();
  Eigen::Vector2d meas = Eigen::Vector2d::Zero();
};

// A field model: where a command lands on the plate plane, galvo frame.
class FieldModel {
 public:
  virtual ~FieldModel() = default;
  virtual std::string name() const = 0;
  virtual Eigen::Vector2d Predict(const Eigen::Vector3d& cmd) const = 0;
  // The command that lands on `target` (inverse of Predict by Newton, within 1e-7 mm).
  // False if it does not converge.
  bool CommandFor(const Eigen::Vector3d& target, Eigen::Vector3d* cmd) const;
};

// Measurements in the galvo frame.
struct GalvoSample {
  Eigen::Vector3d cmd = Eigen::Vector3d::Zero();
  Eigen::Vector2d meas = Eigen::Vector2d::Zero();
};

// Bilinear lookup on a regular grid of commands: the error meas - cmd at every node, bilinear
// between nodes, the nearest edge's beyond. Needs every node of an nx x ny grid (>= 2 x 2).
class BilinearFieldModel : public FieldModel {
 public:
  // Errors: invalid_argument when the samples are not a complete regular grid (names the
  // missing node).
  static Result<BilinearFieldModel> Fit(const std::vector<GalvoSample>& nodes);
  std::string name() const override;
  Eigen::Vector2d Predict(const Eigen::Vector3d& cmd) const override;
  Eigen::Vector2d ErrorAt(double x_mm, double y_mm) const { return error_.At(x_mm, y_mm); }
  int nx() const { return static_cast<int>(error_.xs().size()); }
  int ny() const { return static_cast<int>(error_.ys().size()); }
  const optics::GridTable& table() const { return error_; }

 private:
  optics::GridTable error_;  // meas - cmd at the nodes
};

// Seed 003's quadrant curve fit from 9 points: the centre, the four axis points (+-X, 0),
// (0, +-Y) and the four corners (+-X, +-Y) of a grid. Its equations (10) and (11) are figures
// in the seed; insitu reads them as the two-mirror forms the seed derives in sec. 1.2: a
// linear map per half axis from the centre and axis points, then per quadrant q
//   dx = k_q x y^2,  dy = k'_q y x^2
// with k_q, k'_q from that quadrant's corner (8 coefficients, as the seed counts).
class QuadrantFieldModel : public FieldModel {
 public:
  // Errors: invalid_argument when one of the 9 points is missing (named).
  static Result<QuadrantFieldModel> Fit(const std::vector<GalvoSample>& samples, double half_x_mm,
                                        double half_y_mm);
  std::string name() const override { return "quadrant"; }
  Eigen::Vector2d Predict(const Eigen::Vector3d& cmd) const override;

 private:
  Eigen::Vector2d centre_ = Eigen::Vector2d::Zero();
  // Measured axis points minus the centre, per half axis: +x, -x, +y, -y.
  Eigen::Vector2d axis_[4];
  double half_x_ = 1, half_y_ = 1;
  double k_[4] = {0, 0, 0, 0}, kp_[4] = {0, 0, 0, 0};  // quadrants ++, -+, --, +-
};

// The physical head: which of its parameters to fit. The rest stay at the design's values.
struct HeadFitOptions {
  bool fit_focal_length = true;
  bool fit_ftheta_distortion = true;  // c3 and c5
  // The difference of the two axis tilts shears the field and is fitted as the X axis's tilt;
  // their common part is nearly a rotation of the field, which the board's placement absorbs.
  bool fit_axis_tilt = true;
  // The Y axis's tilt too: not quite a rotation (it grows with the field angle; 1 mrad of it
  // leaves ~3.4 um when only the X tilt is fitted), but with the plate's placement free the
  // two tilts and the placement's turn are nearly degenerate: on the as-built head of
  // field_models_test, fitting it took the tilts' standard errors from 0.02 to 0.23 mrad.
  bool fit_y_axis_tilt = false;
  // Zero offsets move the whole field (the board's placement takes that) and centre its
  // distortion off the command origin only in second order (3 mrad of them leave ~11 um; the
  // usual 0.1-1 mrad, ~1 um): fitted only when asked, as they are poorly determined beside
  // the placement (0.07-0.2 mrad standard errors on the as-built head).
  bool fit_zero_offsets = false;
  int max_iterations = 200;

  Status Validate() const;
};

struct HeadParamFit {
  std::string name;  // focal_length_mm, ftheta_c3, ftheta_c5, x_axis_tilt_mrad, ...
  double value = 0.0;
  double stderr_value = 0.0;  // NaN where the covariance is singular
};

// The fitted physical head and the plate-to-galvo motion.
class HeadFieldFit : public FieldModel {
 public:
  // Fits `samples` (plate frame) with the design geometry `design` as the controller's
  // correction. Errors: failed_precondition for fewer than 6 samples, or when the solver does
  // not converge (its report in the message).
  // `beam`: the path of the beam that made the targets, against the head's own (the marking
  // beam's): the pointer's measured path when its spots stand for the targets, so that the
  // fitted head is still the marking beam's. Predict() is then that beam's.
  static Result<HeadFieldFit> Fit(const std::vector<TargetSample>& samples,
                                  const optics::HeadGeometry& design, const HeadFitOptions& options,
                                  const optics::BeamPath& beam = {});
  std::string name() const override { return "physics"; }
  Eigen::Vector2d Predict(const Eigen::Vector3d& cmd) const override;

  const optics::HeadModel& head() const { return head_; }
  const Eigen::Isometry2d& galvo_from_plate() const { return galvo_from_plate_; }
  const std::vector<HeadParamFit>& params() const { return params_; }
  double rms_mm() const { return rms_mm_; }
  const std::string& summary() const { return summary_; }
  // Plate-frame samples in the galvo frame.
  std::vector<GalvoSample> ToGalvo(const std::vector<TargetSample>& samples) const;

 private:
  optics::HeadModel head_;
  optics::BeamPath beam_;
  Eigen::Isometry2d galvo_from_plate_ = Eigen::Isometry2d::Identity();
  std::vector<HeadParamFit> params_;
  double rms_mm_ = 0.0;
  std::string summary_;
};

// Physics first, and a bilinear table of what it leaves at the grid nodes.
class PhysicsPlusTableModel : public FieldModel {
 public:
  // `nodes`: the grid nodes in the galvo frame. Errors as BilinearFieldModel::Fit.
  static Result<PhysicsPlusTableModel> Fit(const HeadFieldFit& physics,
                                           const std::vector<GalvoSample>& nodes);
  std::string name() const override { return "physics+table"; }
  Eigen::Vector2d Predict(const Eigen::Vector3d& cmd) const override;
  const BilinearFieldModel& residual() const { return residual_; }

 private:
  HeadFieldFit physics_;
  BilinearFieldModel residual_;
};

// The path of a second beam through a known head (the red pointer against the marking laser
// the head was fitted to): its input misalignment and lateral colour, from where its spots were
// measured (galvo frame). Errors: failed_precondition for fewer than 4 spots, or when the solver
// does not converge.
// With `fit_mirror_separation`, the head's mirror separation is fitted too: it tilts the chief
// rays (the pupil's shift) and so shows only in spots at two heights or more (>= 2 mm apart,
// else failed_precondition).
struct BeamPathFit {
  optics::BeamPath path;
  double mirror_separation_mm = 0.0;  // fitted, or the head's as given
  double stderr_offset_x_mrad = 0, stderr_offset_y_mrad = 0, stderr_lateral_colour_pct = 0;
  double stderr_mirror_separation_mm = 0;  // 0 when not fitted
  double rms_mm = 0.0;  // of the spots about the fitted path
};
Result<BeamPathFit> FitBeamPath(const optics::HeadModel& head,
                                const std::vector<GalvoSample>& spots,
                                bool fit_mirror_separation = false);

// rms and max of |meas - model.Predict(cmd)| over samples (galvo frame), mm.
struct ModelError {
  double rms_mm = 0.0;
  double max_mm = 0.0;
};
ModelError PredictionError(const FieldModel& model, const std::vector<GalvoSample>& samples);
// The nominal model (a command lands where it asks): rms and max of |meas - cmd|.
ModelError NominalError(const std::vector<GalvoSample>& samples);

}  // namespace insitu::fit
