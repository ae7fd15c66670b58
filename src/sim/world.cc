#include "insitu/sim/world.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <thread>

#include "insitu/core/log.h"
#include "insitu/fit/extension.h"
#include "sim/mark_map.h"
#include "sim/noise.h"
#include "sim/parallel.h"

namespace insitu::sim {
namespace {

// CameraOptions::pixel_format's names (validated there).
PixelFormat PixelFormatOfName(const std::string& name) {
  for (PixelFormat f : {PixelFormat::kBayerRG, PixelFormat::kBayerGR, PixelFormat::kBayerGB,
                        PixelFormat::kBayerBG}) {
    if (name == PixelFormatName(f)) return f;
  }
  return PixelFormat::kMono;
}

constexpr double kPlanck = 6.62607015e-34;   // J s
constexpr double kLightSpeed = 299792458.0;  // m / s
// Photons per second per m^2 per lux of white (LED, ~4000 K) light: 1 lux ~ 3.3 mW/m^2 at a
// mean photon energy of 3.6e-19 J.
constexpr double kWhitePhotonsPerLuxSecondM2 = 9.0e15;
// Height from which beam rays are traced down (above any part).
constexpr double kTraceStartHeightMm = 200.0;

CameraOptions BinnedCamera(const CameraOptions& o, int b) {
  CameraOptions c = o;
  c.width_px = o.width_px / b;
  c.height_px = o.height_px / b;
  c.pixel_pitch_um = o.pixel_pitch_um * b;
  c.principal_point_offset_px = {o.principal_point_offset_px[0] / b,
                                 o.principal_point_offset_px[1] / b};
  return c;
}

}  // namespace

SimWorld::SimWorld(const WorldOptions& options)
    : options_(options),
      scene_(std::make_unique<Scene>(options.part, options.stage)),
      true_optics_(std::make_unique<ScanOptics>(options.scan_head.optics)),
      design_optics_(std::make_unique<ScanOptics>(options.scan_head.design)),
      camera_full_(std::make_unique<CameraModel>(options.camera)),
      exposure_us_(options.camera.exposure_ms * 1e3),
      stage_commanded_z_(options.stage.z_mm),
      gain_db_(options.camera.gain_db) {
  camera_binned_ = std::make_unique<CameraModel>(options.camera);
  marks_ = NewMarkMap();
  std::vector<fit::EffectParams> effects;
  for (const FieldEffectOption& e : options.scan_head.field_effects)
    effects.push_back({e.name, e.params});
  auto ext = fit::ModelExtension::Make(effects);  // valid: WorldOptions::Validate() checked it
  field_effects_ = std::make_unique<fit::ModelExtension>(ext.ok() ? *ext : fit::ModelExtension());
  scene_->SetBoard(options.board, -1);
  head_rng_.seed(options.seed * 0x9E3779B97F4A7C15ull + 0x5EEDull);
  profiler_rng_.seed(options.seed * 0xD1B54A32D192ED03ull + 0x9A0Full);
  profiler_exposure_us_ = options.profiler.exposure_us;
  block_cos_ = std::cos(options.block.rotation_deg * M_PI / 180.0);
  block_sin_ = std::sin(options.block.rotation_deg * M_PI / 180.0);
}

std::unique_ptr<MarkMap> SimWorld::NewMarkMap() const {
  // A panel's grooves are half a millimetre wide and a few hundred um deep: 10 um cells hold
  // their shape to a fraction of a um between the profiler's 25 um points, at a sixth of the
  // memory of the 4 um cells that marks on metal need (a 200 mm panel's grooves: ~100 MB).
  return std::make_unique<MarkMap>(options_.part.kind == "panel" ? 0.010
                                                                 : MarkMap::kFineCellMm);
}

void SimWorld::NewSettleError() {
  const double s = options_.scan_head.repeatability_urad * 1e-6;
  if (!(s > 0)) return;
  std::normal_distribution<double> n(0.0, s);
  settle_error_ = {n(head_rng_), n(head_rng_)};
}

void SimWorld::RemovePart() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  options_.part.kind = "none";
  const double z = scene_->stage_z();
  scene_ = std::make_unique<Scene>(options_.part, options_.stage);
  scene_->set_stage_z(z);
  scene_->SetBoard(options_.board, -1);
  ambient_valid_ = false;
  now_s_ += 5.0;  // the operator's hands
}

void SimWorld::RemoveBoard() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  scene_->SetBoard(options_.board, -1);
  ambient_valid_ = false;
}

Status SimWorld::PlaceBoard(int index) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!options_.board.present) return FailedPrecondition("there is no calibration board");
  if (index < 0) return InvalidArgument("board pose index must be >= 0");
  scene_->SetBoard(options_.board, index);
  ambient_valid_ = false;
  now_s_ += 5.0;  // the operator's hands
  return Status::Ok();
}

Status SimWorld::PlaceBoardOnPlate() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!options_.board.present) return FailedPrecondition("there is no calibration board");
  const auto& p = options_.board.plate_pose;
  scene_->SetBoardPose(options_.board, {p[0], p[1], scene_->stage_z() + p[2], 0.0, 0.0, p[3]});
  ambient_valid_ = false;
  now_s_ += 5.0;  // the operator's hands
  return Status::Ok();
}

void SimWorld::FreshPlate() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  marks_ = NewMarkMap();
  pulses_.clear();
  ambient_valid_ = false;
  now_s_ += 30.0;  // the operator's hands
}

int SimWorld::board_pose_count() const {
  return options_.board.present ? static_cast<int>(options_.board.poses.size()) : 0;
}

SimWorld::~SimWorld() = default;

double SimWorld::now_s() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return now_s_;
}
void SimWorld::Advance(double seconds) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  now_s_ += std::max(0.0, seconds);
  PaceTo(now_s_);
  triggered_wake_.notify_all();
}

void SimWorld::PaceTo(double t) {
  const double factor = options_.real_time_factor;
  if (!(factor > 0)) return;
  const auto wall = std::chrono::steady_clock::now();
  const auto due = pace_wall0_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>((t - pace_virtual0_) / factor));
  if (!paced_ || wall > due + std::chrono::milliseconds(50)) {
    paced_ = true;  // first call, or the simulation fell behind: start again from here
    pace_wall0_ = wall;
    pace_virtual0_ = t;
    return;
  }
  if (due > wall) std::this_thread::sleep_until(due);
}

const CameraModel& SimWorld::true_camera() const { return *camera_full_; }
const Scene& SimWorld::scene() const { return *scene_; }
const ScanOptics& SimWorld::true_optics() const { return *true_optics_; }

bool SimWorld::CommandToAngles(const Eigen::Vector3d& p, MirrorAngles* angles) const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);  // the board's correction may change
  // The head's correction table is built from its design geometry; the mirrors' zero errors,
  // and any field effects the world carries (measured reality), are what the real head adds
  // on top.
  // The command as the controller sends it: command_bits over the field.
  const auto& sh = options_.scan_head;
  const double step = 2.0 * sh.field_half_size_mm / std::ldexp(1.0, sh.command_bits);
  Eigen::Vector2d xy(std::round(p.x() / step) * step, std::round(p.y() / step) * step);
  if (board_correction_) xy = board_correction_(xy);
  if (!field_effects_->empty()) xy = field_effects_->Forward(xy, p.z());
  if (sh.own_correction) {
    if (!design_optics_->Solve(xy.x(), xy.y(), p.z(), angles)) return false;
  } else {
    // Driven linearly: the galvo gains make a small command land where it asks on the design
    // objective, and nothing corrects the rest.
    const double f = sh.design.focal_length_mm;
    angles->x_rad = xy.x() / f;
    angles->y_rad = xy.y() / f;
  }
  angles->x_rad += sh.x_zero_offset_mrad * 1e-3 + settle_error_.x_rad;
  angles->y_rad += sh.y_zero_offset_mrad * 1e-3 + settle_error_.y_rad;
  return true;
}

void SimWorld::SetBoardCorrection(
    const void* owner, std::function<Eigen::Vector2d(const Eigen::Vector2d&)> correction) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  board_correction_ = std::move(correction);
  board_correction_owner_ = owner;
}

void SimWorld::ClearBoardCorrection(const void* owner) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (board_correction_owner_ != owner) return;
  board_correction_ = {};
  board_correction_owner_ = nullptr;
}

Status SimWorld::StartPointerLine(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                                  double speed_mm_per_s) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const auto& sh = options_.scan_head;
  for (const Eigen::Vector3d& p : {from, to}) {
    if (std::abs(p.x()) > sh.field_half_size_mm || std::abs(p.y()) > sh.field_half_size_mm) {
      return OutOfRange("pointer line point (" + std::to_string(p.x()) + ", " +
                        std::to_string(p.y()) + ") mm is outside the scan field +-" +
                        std::to_string(sh.field_half_size_mm) + " mm");
    }
    if (std::abs(p.z()) > sh.focus_range_mm) {
      return OutOfRange("focus z " + std::to_string(p.z()) + " mm is outside the focus range +-" +
                        std::to_string(sh.focus_range_mm) + " mm");
    }
  }
  if (!(speed_mm_per_s > 0.0)) return InvalidArgument("pointer speed must be positive");
  // Where the mirrors rest now: on the running program's current command, else as they were.
  if (pointer_) CommandToAngles(PointerCommandAt(now_s_), &rest_angles_);
  pointer_ = PointerProgram{from, to, speed_mm_per_s, now_s_};
  NewSettleError();
  return Status::Ok();
}

void SimWorld::StopPointer() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (pointer_) CommandToAngles(PointerCommandAt(now_s_), &rest_angles_);
  pointer_.reset();
}

Eigen::Vector3d SimWorld::PointerCommandAt(double t) const {
  const PointerProgram& p = *pointer_;
  const double length = (p.to - p.from).norm();
  if (length < 1e-9) return p.from;
  // Back and forth at constant speed (triangle wave along the segment).
  const double s = std::fmod((t - p.start_s) * p.speed_mm_per_s, 2.0 * length);
  const double along = s <= length ? s : 2.0 * length - s;
  return p.from + (p.to - p.from) * (along / length);
}

void SimWorld::PointerSamples(double t0, double t1, std::vector<BeamSample>* samples) const {
  const auto& sh = options_.scan_head;
  const double tick = sh.clock_us * 1e-6;
  const double tau = sh.tracking_lag_ms * 1e-3;
  // The lag forgets its past within ~10 tau: start the simulation there (or at program start).
  double t = std::max(pointer_->start_s, t0 - 10.0 * tau - tick);
  MirrorAngles actual = rest_angles_;
  if (t > pointer_->start_s) CommandToAngles(PointerCommandAt(t), &actual);
  const double alpha = tau > 0 ? 1.0 - std::exp(-tick / tau) : 1.0;
  // Sub-samples per tick: fine enough that the spot moves < 0.02 mm between samples.
  const int sub = std::max(1, static_cast<int>(std::ceil(pointer_->speed_mm_per_s * tick / 0.02)));
  MirrorAngles prev = actual;
  for (; t < t1; t += tick) {
    MirrorAngles cmd;
    CommandToAngles(PointerCommandAt(t + tick), &cmd);
    actual.x_rad += alpha * (cmd.x_rad - actual.x_rad);
    actual.y_rad += alpha * (cmd.y_rad - actual.y_rad);
    const double z = PointerCommandAt(t + tick).z();
    for (int k = 1; k <= sub; ++k) {
      const double ts = t + tick * k / sub;
      if (ts <= t0 || ts > t1) continue;
      const double f = static_cast<double>(k) / sub;
      BeamSample s;
      s.angles.x_rad = prev.x_rad + f * (actual.x_rad - prev.x_rad);
      s.angles.y_rad = prev.y_rad + f * (actual.y_rad - prev.y_rad);
      s.focus_z_mm = z;
      s.dt_s = tick / sub;
      samples->push_back(s);
    }
    prev = actual;
  }
}

Status SimWorld::ExecuteMarkingList(const std::vector<ListMove>& moves, const MarkingParams& p,
                                    const std::atomic<bool>* abort,
                                    const std::function<void(double)>& progress) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!(p.jump_speed_mm_per_s > 0) || !(p.mark_speed_mm_per_s > 0)) {
    return InvalidArgument("list speeds must be > 0");
  }
  if (!(p.power_fraction >= 0 && p.power_fraction <= 1)) {
    return InvalidArgument("laser power must be a fraction in [0, 1]");
  }
  if (!(p.pulse_frequency_khz > 0)) return InvalidArgument("pulse frequency must be > 0");
  for (double d : {p.laser_on_delay_us, p.laser_off_delay_us, p.jump_delay_us, p.mark_delay_us}) {
    if (!(d >= 0)) return InvalidArgument("list delays must be >= 0");
  }
  const auto& sh = options_.scan_head;
  for (const ListMove& m : moves) {
    MirrorAngles a;
    if (std::abs(m.to_in_galvo.x()) > sh.field_half_size_mm ||
        std::abs(m.to_in_galvo.y()) > sh.field_half_size_mm ||
        std::abs(m.to_in_galvo.z()) > sh.focus_range_mm || !CommandToAngles(m.to_in_galvo, &a)) {
      return OutOfRange("list point (" + std::to_string(m.to_in_galvo.x()) + ", " +
                        std::to_string(m.to_in_galvo.y()) + ", " +
                        std::to_string(m.to_in_galvo.z()) +
                        ") mm is outside the field or focus range");
    }
  }
  const double tick = sh.clock_us * 1e-6;
  const auto ticks_of = [&](double us) { return static_cast<int>(std::llround(us * 1e-6 / tick)); };

  // 1. The command on the head's clock, one move at a time: position and laser state per tick.
  // A move's ticks are final once the next move starts (the laser delays reach only into their
  // own move's ticks), so a list is never held whole at one entry per 10 us.
  struct Tick {
    Eigen::Vector3d command;
    bool laser = false;
  };
  const double tau = sh.tracking_lag_ms * 1e-3;
  const int settle = static_cast<int>(std::ceil(10.0 * tau / tick));
  struct Cursor {
    Eigen::Vector3d at;
    int64_t laser_off_at = -1;  // list tick at which a pending laser-off happens
  };
  // Move i's ticks (i == moves.size(): the mirrors settling with the laser off at the end),
  // the first of them at list tick `base`.
  const auto emit = [&](size_t i, int64_t base, Cursor* c, std::vector<Tick>* out) {
    out->clear();
    const auto end = [&] { return base + static_cast<int64_t>(out->size()); };
    if (i == moves.size()) {
      for (int k = 0; k < settle; ++k) out->push_back({c->at, c->laser_off_at > end()});
      return;
    }
    const ListMove& m = moves[i];
    const bool mark = m.kind == ListMove::Kind::kMark;
    const bool starts_sequence = mark && (i == 0 || moves[i - 1].kind != ListMove::Kind::kMark);
    const bool ends_sequence =
        mark && (i + 1 == moves.size() || moves[i + 1].kind != ListMove::Kind::kMark);
    const double speed = mark ? p.mark_speed_mm_per_s : p.jump_speed_mm_per_s;
    const int n =
        std::max(1, static_cast<int>(std::ceil((m.to_in_galvo - c->at).norm() / (speed * tick))));
    for (int k = 1; k <= n; ++k) {
      out->push_back({c->at + (m.to_in_galvo - c->at) * (static_cast<double>(k) / n), mark});
    }
    if (starts_sequence) {
      // The laser comes on laser_on_delay after the sequence's first mark starts.
      const size_t on = std::min(out->size(), static_cast<size_t>(ticks_of(p.laser_on_delay_us)));
      for (size_t k = 0; k < on; ++k) (*out)[k].laser = false;
    }
    c->at = m.to_in_galvo;
    if (ends_sequence) {
      const int hold = ticks_of(p.mark_delay_us);
      for (int k = 0; k < hold; ++k) out->push_back({c->at, false});
      const int64_t reached = end() - hold;
      c->laser_off_at = reached + ticks_of(p.laser_off_delay_us);
      // The laser stays on for laser_off_delay after the command reached the end.
      for (int64_t k = reached; k < c->laser_off_at && k < end(); ++k)
        (*out)[k - base].laser = true;
    }
    if (!mark) {
      for (int k = 0, hold = ticks_of(p.jump_delay_us); k < hold; ++k) {
        out->push_back({c->at, false});
      }
      // A laser-off delay running into the jump keeps the laser on during it.
      for (int64_t k = base; k < c->laser_off_at && k < end(); ++k) (*out)[k - base].laser = true;
    }
  };
  // The list's length, for progress and the abort record: the moves generated once, counted.
  std::vector<Tick> ticks;
  int64_t total = 0;
  {
    Cursor c{last_command_};
    for (size_t i = 0; i <= moves.size(); ++i) {
      emit(i, total, &c, &ticks);
      total += static_cast<int64_t>(ticks.size());
    }
  }

  // 2. The mirrors follow with their lag; pulses fire at the pulse rate while the laser is on.
  const BeamOptions& beam = sh.marking;
  const double w0 = 0.5 * beam.waist_diameter_mm;
  const double rayleigh = M_PI * w0 * w0 / (beam.m2 * beam.wavelength_nm * 1e-6);
  const double pulse_energy_j =
      beam.power_mw * 1e-3 * p.power_fraction / (p.pulse_frequency_khz * 1e3);
  const double pulse_period = 1.0 / (p.pulse_frequency_khz * 1e3);
  const double alpha = tau > 0 ? 1.0 - std::exp(-tick / tau) : 1.0;
  MirrorAngles actual = rest_angles_;
  double t = 0.0, next_pulse = 0.0;
  bool was_on = false;
  const double list_s = static_cast<double>(total) * tick;
  const int64_t pace_every = std::max<int64_t>(1, std::llround(1e-3 / tick));   // 1 ms
  const int64_t report_every = std::max<int64_t>(1, std::llround(0.1 / tick));  // 100 ms
  Cursor cursor{last_command_};
  int64_t i = 0;  // list tick
  for (size_t move = 0; move <= moves.size(); ++move) {
    // A jump ends where the mirrors settle this time: their repeatability.
    if (move < moves.size() && moves[move].kind == ListMove::Kind::kJump) NewSettleError();
    emit(move, i, &cursor, &ticks);
    for (const Tick& k : ticks) {
      ++i;
      if (abort != nullptr && abort->load(std::memory_order_relaxed)) {
        // The laser goes off on this tick; the mirrors hold where the command was.
        last_abort_ = {true, now_s_, now_s_ + list_s, now_s_ + t, std::chrono::steady_clock::now()};
        now_s_ += t;
        last_command_ = k.command;
        rest_angles_ = actual;
        char done[96];
        std::snprintf(done, sizeof done, "list aborted after %.1f of %.1f ms; laser off", t * 1e3,
                      list_s * 1e3);
        return Status(StatusCode::kCancelled, done);
      }
      if ((i - 1) % pace_every == 0) PaceTo(now_s_ + t);
      if (progress && i > 1 && (i - 1) % report_every == 0) progress(t / list_s);
      MirrorAngles cmd;
      CommandToAngles(k.command, &cmd);
      actual.x_rad += alpha * (cmd.x_rad - actual.x_rad);
      actual.y_rad += alpha * (cmd.y_rad - actual.y_rad);
      t += tick;
      if (!k.laser) {
        was_on = false;
        continue;
      }
      ++laser_on_ticks_;
      if (!was_on) next_pulse = t;  // the pulse train starts with the laser
      was_on = true;
      for (; next_pulse <= t; next_pulse += pulse_period) {
        const ChiefRay ray = true_optics_->Trace(actual, options_.scan_head.marking.Path());
        const Eigen::Vector3d start = ray.AtHeight(scene_->stage_z() + kTraceStartHeightMm);
        Hit hit;
        if (!scene_->Intersect(start, -ray.up, 5000.0, &hit)) continue;
        MarkPulse pulse;
        pulse.t_s = now_s_ + next_pulse;
        pulse.point_in_world = hit.point_in_world;
        pulse.on_part = hit.on_part;
        pulse.defocus_mm = (k.command.z() - hit.point_in_world.z()) / ray.up.z();
        const double w_mm = w0 * std::sqrt(1.0 + std::pow(pulse.defocus_mm / rayleigh, 2));
        // Peak fluence of a Gaussian pulse, J/cm^2: 2 E / (pi w^2), w in cm.
        const double f0 = 2.0 * pulse_energy_j / (M_PI * std::pow(w_mm * 0.1, 2));
        const PartOptions& part = options_.part;
        const bool film = hit.on_part && part.kind == "panel" && part.maskant_thickness_mm > 0;
        const double threshold = film           ? part.maskant_ablation_threshold_j_per_cm2
                                 : hit.on_part ? part.ablation_threshold_j_per_cm2
                                               : options_.stage.plate_ablation_threshold_j_per_cm2;
        pulse.diameter_mm = f0 > threshold ? w_mm * std::sqrt(2.0 * std::log(f0 / threshold)) : 0.0;
        pulse.beam_radius_mm = w_mm;
        if (film) {
          marks_->AddFilmCrater(hit.point_in_world.x(), hit.point_in_world.y(), w_mm,
                                std::log(f0 / threshold), part.maskant_ablation_depth_um,
                                1e3 * part.maskant_thickness_mm,
                                std::log(f0 / part.ablation_threshold_j_per_cm2),
                                part.ablation_depth_um);
        } else {
          marks_->AddCrater(hit.point_in_world.x(), hit.point_in_world.y(),
                            0.5 * pulse.diameter_mm, w_mm, part.ablation_depth_um);
        }
        if (pulse.diameter_mm > 0) ambient_valid_ = false;  // the cameras see the new marks
        pulses_.push_back(pulse);
      }
    }
  }
  now_s_ += t;
  last_command_ = cursor.at;
  rest_angles_ = actual;
  PaceTo(now_s_);
  if (progress) progress(1.0);
  return Status::Ok();
}

Status SimWorld::MoveHead(const Eigen::Vector3d& point_in_galvo) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return ExecuteMarkingList({{ListMove::Kind::kJump, point_in_galvo}}, MarkingParams{});
}

double SimWorld::MarkFactor(double x, double y, double half, bool on_part) const {
  if (marks_->empty()) return 1.0;
  const PartOptions& po = options_.part;
  const double marked = on_part ? po.marked_reflectance : options_.stage.plate_marked_reflectance;
  const auto factor = [&](double depth_um) {
    return marked + (1.0 - marked) * std::exp(-depth_um / po.darkening_depth_um);
  };
  double x0, y0, x1, y1;
  marks_->Bounds(&x0, &y0, &x1, &y1);
  if (x + half < x0 || x - half > x1 || y + half < y0 || y - half > y1) return 1.0;
  // A footprint wider than the map's cells: average samples one cell apart (at most 16 x 16).
  const int n = std::clamp(static_cast<int>(std::ceil(2.0 * half / marks_->cell_mm())), 1, 16);
  double sum = 0.0;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double sx = n == 1 ? x : x - half + 2.0 * half * (i + 0.5) / n;
      const double sy = n == 1 ? y : y - half + 2.0 * half * (j + 0.5) / n;
      sum += factor(marks_->DepthUm(sx, sy));
    }
  }
  return sum / (n * n);
}

Status SimWorld::MoveStage(double z_mm) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const auto& st = options_.stage;
  if (z_mm < st.min_z_mm || z_mm > st.max_z_mm) {
    return OutOfRange("stage z " + std::to_string(z_mm) + " mm is outside the travel [" +
                      std::to_string(st.min_z_mm) + ", " + std::to_string(st.max_z_mm) + "] mm");
  }
  const double true_z = z_mm * (1.0 + st.scale_error_ppm * 1e-6);
  now_s_ += std::abs(true_z - scene_->stage_z()) / st.speed_mm_per_s;
  PaceTo(now_s_);
  scene_->set_stage_z(true_z);
  stage_commanded_z_ = z_mm;
  return Status::Ok();
}

double SimWorld::stage_z() const { return scene_->stage_z(); }
double SimWorld::stage_commanded_z() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return stage_commanded_z_;
}

Status SimWorld::SetExposure(double exposure_us) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!(exposure_us >= 10.0 && exposure_us <= 10e6)) {
    return OutOfRange("exposure " + std::to_string(exposure_us) +
                      " us is outside the camera's range [10, 1e7] us");
  }
  exposure_us_ = exposure_us;
  return Status::Ok();
}

Status SimWorld::SetGain(double gain_db) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!(gain_db >= 0.0 && gain_db <= 24.0)) {
    return OutOfRange("gain " + std::to_string(gain_db) + " dB is outside [0, 24] dB");
  }
  gain_db_ = gain_db;
  return Status::Ok();
}

Status SimWorld::SetBinning(int binning) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (binning != 1 && binning != 2 && binning != 4) {
    return InvalidArgument("binning " + std::to_string(binning) + " not supported (1, 2 or 4)");
  }
  binning_ = binning;
  camera_binned_ = std::make_unique<CameraModel>(BinnedCamera(options_.camera, binning));
  return Status::Ok();
}

Status SimWorld::SetRegion(int first_row, int rows) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const int h = options_.camera.height_px;
  if (rows < 0 || first_row < 0 || (rows > 0 && first_row + rows > h)) {
    return OutOfRange("region: rows " + std::to_string(first_row) + ".." +
                      std::to_string(first_row + rows) + " outside the sensor's 0.." +
                      std::to_string(h));
  }
  region_first_row_ = rows == 0 ? 0 : first_row;
  region_rows_ = rows;
  return Status::Ok();
}

int SimWorld::binning() const { return binning_; }
double SimWorld::exposure_us() const { return exposure_us_; }

Result<Frame> SimWorld::Grab() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  double link_s = 0.0;
  INSITU_ASSIGN_OR_RETURN(Frame frame, Expose(now_s_, &link_s));
  now_s_ += exposure_us_ * 1e-6 + link_s;
  PaceTo(now_s_);
  triggered_wake_.notify_all();
  return frame;
}

double SimWorld::LinkSeconds(size_t bytes) const {
  const double rate = options_.camera.link_mb_per_s;
  return rate > 0 ? static_cast<double>(bytes) / (rate * 1e6) : 0.0;
}

double SimWorld::MaxFrameRateHz() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const CameraOptions cam = BinnedCamera(options_.camera, binning_);
  int rows = cam.height_px;
  if (region_rows_ > 0) {
    rows = std::min(cam.height_px, (region_first_row_ + region_rows_ + binning_ - 1) / binning_) -
           region_first_row_ / binning_;
  }
  const size_t bytes = static_cast<size_t>(cam.width_px) * rows * (cam.bit_depth > 8 ? 2 : 1);
  // The sensor exposes the next frame while the last one crosses the link.
  return 1.0 / std::max(exposure_us_ * 1e-6, LinkSeconds(bytes));
}

void SimWorld::ArmTrigger(bool armed) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  trigger_armed_ = armed && options_.camera.head_trigger;
  head_started_ = false;
  triggered_.clear();
  // The camera is idle once (re)armed: an exposure or a frame on the link from before (a
  // sweep aborted mid-exposure) is over, its frame dropped with the rest.
  exposing_until_s_ = std::min(exposing_until_s_, now_s_);
  link_free_s_ = std::min(link_free_s_, now_s_);
  ignored_pulses_ = 0;
  triggered_wake_.notify_all();
}

void SimWorld::TriggerPulse() {
  std::unique_lock<std::recursive_mutex> lock(mutex_);
  if (!trigger_armed_) return;
  // Virtual time stays causal across threads: the host takes the frames that have arrived by
  // now before the head goes on, as it would on a real cell, where the head's time is the
  // host's. (The head's thread takes the world's lock for every step; without this wait it
  // runs the whole scan before the host's thread gets the lock once.) A host that takes no
  // frames at all holds the head up for at most 1 s of this computer's time per pulse.
  triggered_wake_.wait_for(lock, std::chrono::seconds(1), [this] {
    return triggered_.empty() || triggered_.front().arrival_s > now_s_;
  });
  if (now_s_ < exposing_until_s_) {  // still exposing the last frame: the edge is lost
    ++ignored_pulses_;
    return;
  }
  double link_s = 0.0;
  auto frame = Expose(now_s_, &link_s);
  exposing_until_s_ = now_s_ + exposure_us_ * 1e-6;
  // Frames leave one after another: this one once exposed and once the link is free.
  link_free_s_ = std::max(exposing_until_s_, link_free_s_) + link_s;
  triggered_.push_back({std::move(frame), link_free_s_});
  triggered_wake_.notify_all();
}

void SimWorld::SetHeadRunning(bool running) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  head_running_ = running;
  head_started_ = head_started_ || running;
  triggered_wake_.notify_all();
}

void SimWorld::HeadFailed() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  head_started_ = true;
  head_running_ = false;
  triggered_wake_.notify_all();
}

int SimWorld::ignored_pulses() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return ignored_pulses_;
}

Result<Frame> SimWorld::TakeTriggered(double wall_timeout_s) {
  std::unique_lock<std::recursive_mutex> lock(mutex_);
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(wall_timeout_s));
  // While the head runs, the clock is the head's: a frame is there once it passes the
  // frame's arrival. Once the head has stopped, waiting for the link is this call's own time,
  // and with no frame left none will come. Before the head starts, wait for it.
  const auto ready = [&] {
    return (!triggered_.empty() && (!head_running_ || triggered_.front().arrival_s <= now_s_)) ||
           (triggered_.empty() && head_started_ && !head_running_);
  };
  const bool woke = triggered_wake_.wait_until(lock, deadline, ready);
  if (!woke) {
    return Status(StatusCode::kDeviceError, "camera: no triggered frame within " +
                                                std::to_string(wall_timeout_s) + " s");
  }
  if (triggered_.empty()) {
    return Status(StatusCode::kDeviceError,
                  "camera: no frame: the scan head stopped and no trigger pulse is left (" +
                      std::to_string(ignored_pulses_) +
                      " pulses came while the camera was exposing and were ignored)");
  }
  Triggered next = std::move(triggered_.front());
  triggered_.pop_front();
  triggered_wake_.notify_all();  // a head waiting for this take goes on
  if (next.arrival_s > now_s_) {
    now_s_ = next.arrival_s;
    PaceTo(now_s_);
  }
  return std::move(next.frame);
}

Result<Frame> SimWorld::Expose(double t0, double* link_s_out) {
  const CameraOptions cam_opts = BinnedCamera(options_.camera, binning_);
  const CameraModel& cam = *camera_binned_;
  const int w = cam_opts.width_px, h = cam_opts.height_px;
  const double exposure_s = exposure_us_ * 1e-6;
  const double t1 = t0 + exposure_s;
  const double pixel_area_m2 = std::pow(cam_opts.pixel_pitch_um * 1e-6, 2);
  const double aperture = M_PI / (4.0 * cam_opts.f_number * cam_opts.f_number);
  const auto& light = options_.light;

  // Ambient light: cached radiance image (the scene only changes with the stage).
  if (!ambient_valid_ || ambient_stage_z_ != scene_->stage_z() || ambient_binning_ != binning_) {
    ambient_e_per_s_.assign(static_cast<size_t>(w) * h, 0.0f);
    const double qe = cam_opts.quantum_efficiency;
    const Eigen::Vector3d lamp(light.lamp_position_mm[0], light.lamp_position_mm[1],
                               light.lamp_position_mm[2]);
    const double lamp_d2 = lamp.squaredNorm();  // lamp_lux is at the world's origin
    const bool glow = light.interreflection;
    const int glow_w = (w + kGlowStep - 1) / kGlowStep;
    glow_grid_.assign(glow ? static_cast<size_t>(glow_w) * ((h + kGlowStep - 1) / kGlowStep) : 0,
                      GlowPoint{});
    const double pointer_photon_j =
        kPlanck * kLightSpeed / (options_.scan_head.pointer.wavelength_nm * 1e-9);
    ParallelRows(h, [&](int v_begin, int v_end) {
      for (int v = v_begin; v < v_end; ++v) {
        for (int u = 0; u < w; ++u) {
          const Eigen::Vector2d px(u, v);
          const Eigen::Vector3d dir = cam.PixelRayInWorld(px);
          Hit hit;
          if (!scene_->Intersect(cam.center_in_world(), dir, 5000.0, &hit)) continue;
          double albedo = hit.albedo;
          // A printed pattern's edge inside the pixel: average 4 x 4 sub-pixel rays, so the
          // image carries the true area fraction and not an aliased step.
          const double footprint_mm =
              hit.t * cam_opts.pixel_pitch_um * 1e-3 / cam_opts.lens_focal_length_mm;
          if (hit.on_board && scene_->BoardEdgeDistance(hit.point_in_world) < 1.5 * footprint_mm) {
            double sum = 0.0;
            for (int sy = 0; sy < 4; ++sy) {
              for (int sx = 0; sx < 4; ++sx) {
                const Eigen::Vector2d sub(u - 0.375 + 0.25 * sx, v - 0.375 + 0.25 * sy);
                Hit sh;
                if (scene_->Intersect(cam.center_in_world(), cam.PixelRayInWorld(sub), 5000.0,
                                      &sh)) {
                  sum += sh.albedo;
                }
              }
            }
            albedo = sum / 16.0;
          }
          // A patterned part (the reticle's lines are far finer than a pixel here): its
          // reflectance over the pixel's footprint, not at one point.
          if (hit.on_part) {
            albedo = scene_->PartAlbedoAt(hit.point_in_world.x(), hit.point_in_world.y(),
                                          footprint_mm);
          }
          if (!hit.on_board) {
            albedo *=
                MarkFactor(hit.point_in_world.x(), hit.point_in_world.y(), 0.5 * footprint_mm,
                           hit.on_part);
          }
          // Diffuse room light from above: surfaces facing up get all of it, walls half.
          const double shade = 0.5 + 0.5 * std::max(0.0, hit.normal.z());
          double lux = light.ambient_lux * shade;
          if (light.lamp_lux > 0) {  // a lamp: inverse square, cosine of incidence
            const Eigen::Vector3d to_lamp = lamp - hit.point_in_world;
            const double d2 = to_lamp.squaredNorm();
            lux += light.lamp_lux * lamp_d2 / d2 *
                   std::max(0.0, hit.normal.dot(to_lamp) / std::sqrt(d2));
          }
          const double sensor_lux = albedo * lux * aperture / M_PI * cam.Cos4(px);
          if (glow && u % kGlowStep == 0 && v % kGlowStep == 0) {
            GlowPoint& g = glow_grid_[static_cast<size_t>(v / kGlowStep) * glow_w + u / kGlowStep];
            g.point = hit.point_in_world.cast<float>();
            g.normal = hit.normal.cast<float>();
            g.e_per_s_per_w_m2 = static_cast<float>(albedo / M_PI * aperture * cam.Cos4(px) *
                                                    pixel_area_m2 * qe / pointer_photon_j);
          }
          ambient_e_per_s_[static_cast<size_t>(v) * w + u] =
              static_cast<float>(sensor_lux * pixel_area_m2 * kWhitePhotonsPerLuxSecondM2 * qe);
        }
      }
    });
    ambient_stage_z_ = scene_->stage_z();
    ambient_binning_ = binning_;
    ambient_valid_ = true;
  }

  std::vector<float> stripe(static_cast<size_t>(w) * h, 0.0f);
  std::vector<float> glow;  // interreflection's electrons (no speckle: an extended source)
  truth_ = FrameTruth{};
  if (pointer_) {
    std::vector<BeamSample> samples;
    PointerSamples(t0, t1, &samples);
    const BeamOptions& beam = options_.scan_head.pointer;
    const double lambda_m = beam.wavelength_nm * 1e-9;
    const double photon_j = kPlanck * kLightSpeed / lambda_m;
    const double w0_mm = 0.5 * beam.waist_diameter_mm;
    const double rayleigh_mm = M_PI * w0_mm * w0_mm / (beam.m2 * lambda_m * 1e3);
    const double power_w = beam.power_mw * 1e-3;
    // Blur of the camera: diffraction (Airy core ~ Gaussian sigma 0.42 lambda N) plus the
    // pixel box (variance 1/12 px^2).
    const double diffraction_px =
        0.42 * lambda_m * cam_opts.f_number / (cam_opts.pixel_pitch_um * 1e-6);
    const double blur_var = diffraction_px * diffraction_px + 1.0 / 12.0;
    const Eigen::Vector3d cam_center = cam.center_in_world();
    truth_.samples = static_cast<int>(samples.size());
    // The pointer goes through the mirrors the marking laser's correction set: its own
    // alignment and lateral colour decide where it lands.
    const optics::BeamPath pointer_path = beam.Path();
    const PartOptions& part = options_.part;
    const double lobe_rad = part.specular_lobe_deg * M_PI / 180.0;
    // A spot of 1/e^2 radius w_mm where a beam of power_w along unit d meets `hit`, for dt_s,
    // as the camera sees it; false if the camera cannot (the surface faces away, the part
    // hides it, or it falls outside the sensor).
    auto draw_spot = [&](const Hit& hit, const Eigen::Vector3d& d, double w_mm, double power_w,
                         double dt_s, bool primary) {
      const Eigen::Vector3d& p = hit.point_in_world;
      const Eigen::Vector3d to_cam = cam_center - p;
      if (hit.normal.dot(to_cam) <= 0.0) return false;  // surface faces away from the camera
      if (light.shadows && scene_->Blocked(p, cam_center)) {
        if (primary) ++truth_.occluded_samples;
        return false;
      }
      Eigen::Vector2d p0;
      if (!cam.Project(p, &p0)) return false;
      if (p0.x() < -10 || p0.y() < -10 || p0.x() > w + 10 || p0.y() > h + 10) return false;
      // Footprint on the tangent plane: rho^2 = s^T M s, M = I - g g^T (g: beam direction in
      // tangent coordinates), covariance (w^2/4) M^-1 = (w^2/4)(I + g g^T / (n.d)^2).
      const Eigen::Vector3d& n = hit.normal;
      Eigen::Vector3d t1v =
          n.cross(std::abs(n.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX());
      t1v.normalize();
      const Eigen::Vector3d t2v = n.cross(t1v);
      const double cos_inc = std::abs(n.dot(d));
      if (cos_inc < 1e-3) return false;
      const Eigen::Vector2d g(t1v.dot(d), t2v.dot(d));
      const Eigen::Matrix2d sigma_s =
          (w_mm * w_mm / 4.0) *
          (Eigen::Matrix2d::Identity() + g * g.transpose() / (cos_inc * cos_inc));
      const Eigen::Matrix<double, 2, 3> j3 = cam.ProjectJacobian(p);
      Eigen::Matrix2d j2;
      j2.col(0) = j3 * t1v;
      j2.col(1) = j3 * t2v;
      const Eigen::Matrix2d sigma_geom = j2 * sigma_s * j2.transpose();
      const Eigen::Matrix2d sigma = sigma_geom + blur_var * Eigen::Matrix2d::Identity();
      const Eigen::Matrix2d info = sigma.inverse();
      // The surface's reflectance toward the camera (BRDF, 1/sr): diffuse albedo / pi, and on
      // a glossy part its specular lobe about the mirror direction r, a Gaussian of the angle
      // between r and the view, normalised so the lobe holds `specular` of the light.
      double brdf = hit.albedo / M_PI;
      if (hit.on_part && part.specular > 0) {
        const Eigen::Vector3d r = d - 2.0 * d.dot(n) * n;
        const Eigen::Vector3d view = to_cam.normalized();
        const double cos_o = n.dot(view);
        const double theta = std::acos(std::clamp(r.dot(view), -1.0, 1.0));
        brdf += part.specular * std::exp(-0.5 * theta * theta / (lobe_rad * lobe_rad)) /
                (2.0 * M_PI * lobe_rad * lobe_rad * std::max(cos_o, 0.05));
      }
      // Peak radiance of the spot (W / m^2 / sr), lowered by the blur that spreads it.
      const double w_m = w_mm * 1e-3;
      const double radiance = brdf * 2.0 * power_w / (M_PI * w_m * w_m) * cos_inc *
                              std::sqrt(sigma_geom.determinant() / sigma.determinant());
      const double electrons_peak = radiance * aperture * cam.Cos4(p0) * pixel_area_m2 * dt_s *
                                    cam_opts.quantum_efficiency / photon_j;
      if (primary) {
        truth_.beam_pixels.push_back(p0);
        truth_.beam_points_in_world.push_back(p);
      }
      const double reach_u = 4.0 * std::sqrt(sigma(0, 0)), reach_v = 4.0 * std::sqrt(sigma(1, 1));
      const int u_lo = std::max(0, static_cast<int>(std::floor(p0.x() - reach_u)));
      const int u_hi = std::min(w - 1, static_cast<int>(std::ceil(p0.x() + reach_u)));
      const int v_lo = std::max(0, static_cast<int>(std::floor(p0.y() - reach_v)));
      const int v_hi = std::min(h - 1, static_cast<int>(std::ceil(p0.y() + reach_v)));
      for (int v = v_lo; v <= v_hi; ++v) {
        const double dv = v - p0.y();
        float* row = stripe.data() + static_cast<size_t>(v) * w;
        for (int u = u_lo; u <= u_hi; ++u) {
          const double du = u - p0.x();
          const double q = info(0, 0) * du * du + 2.0 * info(0, 1) * du * dv + info(1, 1) * dv * dv;
          if (q < 32.0) row[u] += static_cast<float>(electrons_peak * std::exp(-0.5 * q));
        }
      }
      return true;
    };
    // Interreflection's sources: the spots' diffuse light, binned on a 0.5 mm grid.
    struct GlowSource {
      Eigen::Vector3d point_sum = Eigen::Vector3d::Zero(), normal_sum = Eigen::Vector3d::Zero();
      double joules = 0.0;  // albedo x energy: what the spot sends back into its half space
      int count = 0;
    };
    std::map<std::array<int64_t, 3>, GlowSource> glow_sources;
    for (const BeamSample& s : samples) {
      const ChiefRay ray = true_optics_->Trace(s.angles, pointer_path);
      const Eigen::Vector3d start = ray.AtHeight(scene_->stage_z() + kTraceStartHeightMm);
      Hit hit;
      if (!scene_->Intersect(start, -ray.up, 5000.0, &hit)) continue;
      const Eigen::Vector3d& p = hit.point_in_world;
      // Beam radius where it meets the surface (Gaussian beam, waist at the focus height).
      const double defocus_mm = (p.z() - s.focus_z_mm) / ray.up.z();
      const double w_mm = w0_mm * std::sqrt(1.0 + std::pow(defocus_mm / rayleigh_mm, 2));
      const Eigen::Vector3d d = -ray.up;
      draw_spot(hit, d, w_mm, power_w, s.dt_s, true);
      if (light.interreflection) {
        GlowSource& src = glow_sources[{std::llround(p.x() * 2.0), std::llround(p.y() * 2.0),
                                        std::llround(p.z() * 2.0)}];
        src.point_sum += p;
        src.normal_sum += hit.normal;
        src.joules += hit.albedo * power_w * s.dt_s;
        ++src.count;
      }
      // A glossy part mirrors `specular` of the beam about its normal; the mirrored beam,
      // widened by the lobe over its path, lights the surface it reaches: a second line.
      if (hit.on_part && part.specular > 0) {
        const Eigen::Vector3d r = d - 2.0 * d.dot(hit.normal) * hit.normal;
        Hit second;
        if (scene_->Intersect(p + r * 1e-3, r, 5000.0, &second)) {
          const double spread = 2.0 * second.t * std::tan(lobe_rad);
          draw_spot(second, r, std::hypot(w_mm, spread), part.specular * power_w, s.dt_s, false);
        }
      }
    }
    // The glow: irradiance I cos(q) / d^2 from each source of intensity albedo P cos(s) / pi,
    // on the grid of surfaces glow_grid_ holds, spread over the pixels bilinearly.
    if (light.interreflection && !glow_sources.empty() && !glow_grid_.empty()) {
      std::vector<GlowSource> sources;
      sources.reserve(glow_sources.size());
      for (auto& [key, src] : glow_sources) {
        src.point_sum /= src.count;
        src.normal_sum.normalize();
        sources.push_back(src);
      }
      const int gw = (w + kGlowStep - 1) / kGlowStep, gh = (h + kGlowStep - 1) / kGlowStep;
      std::vector<float> grid(static_cast<size_t>(gw) * gh, 0.0f);
      ParallelRows(gh, [&](int j0, int j1) {
        for (int j = j0; j < j1; ++j) {
          for (int i = 0; i < gw; ++i) {
            const GlowPoint& g = glow_grid_[static_cast<size_t>(j) * gw + i];
            if (!(g.e_per_s_per_w_m2 > 0.0f)) continue;
            const Eigen::Vector3d q = g.point.cast<double>(), nq = g.normal.cast<double>();
            double joules_per_m2 = 0.0;
            for (const GlowSource& src : sources) {
              const Eigen::Vector3d sq = q - src.point_sum;
              const double d2 = sq.squaredNorm();
              if (d2 < 0.25) continue;  // the spot itself: the stripe
              const double dist = std::sqrt(d2);
              const double cos_s = src.normal_sum.dot(sq) / dist;
              const double cos_q = -nq.dot(sq) / dist;
              if (cos_s <= 0.0 || cos_q <= 0.0) continue;
              joules_per_m2 += src.joules * cos_s * cos_q / (M_PI * d2 * 1e-6);
            }
            grid[static_cast<size_t>(j) * gw + i] =
                static_cast<float>(joules_per_m2 * g.e_per_s_per_w_m2);
          }
        }
      });
      glow.assign(static_cast<size_t>(w) * h, 0.0f);
      for (int v = 0; v < h; ++v) {
        const double y = static_cast<double>(v) / kGlowStep;
        const int j = std::min(static_cast<int>(y), gh - 1), j1 = std::min(j + 1, gh - 1);
        const double fy = y - j;
        for (int u = 0; u < w; ++u) {
          const double x = static_cast<double>(u) / kGlowStep;
          const int i = std::min(static_cast<int>(x), gw - 1), i1 = std::min(i + 1, gw - 1);
          const double fx = x - i;
          const auto at = [&](int ii, int jj) { return grid[static_cast<size_t>(jj) * gw + ii]; };
          glow[static_cast<size_t>(v) * w + u] =
              static_cast<float>((1 - fy) * ((1 - fx) * at(i, j) + fx * at(i1, j)) +
                                 fy * ((1 - fx) * at(i, j1) + fx * at(i1, j1)));
        }
      }
    }
  }

  // Speckle, then photon and read noise, then the ADC.
  const uint64_t frame_seed = SplitMix64(options_.seed * 0x9E3779B97F4A7C15ull + frame_counter_);
  const double grain_px = light.speckle_grain_px > 0
                              ? light.speckle_grain_px
                              : 1.22 * options_.scan_head.pointer.wavelength_nm * 1e-9 *
                                    cam_opts.f_number / (cam_opts.pixel_pitch_um * 1e-6);
  float stripe_max = 0.0f;
  for (float e : stripe) stripe_max = std::max(stripe_max, e);
  truth_.peak_electrons = stripe_max;
  Frame frame;
  frame.width = w;
  frame.height = h;
  frame.bit_depth = cam_opts.bit_depth;
  frame.bytes.resize(static_cast<size_t>(w) * h * frame.bytes_per_pixel());
  frame.sequence = frame_counter_++;
  frame.timestamp_s = t0;
  frame.exposure_us = exposure_us_;
  frame.gain_db = gain_db_;
  frame.binning = binning_;
  const double full_well = cam_opts.full_well_e * binning_ * binning_;
  const double dn_per_e = frame.max_value() / full_well * std::pow(10.0, gain_db_ / 20.0);
  const double read_var = cam_opts.read_noise_e * cam_opts.read_noise_e * binning_ * binning_;
  const double dark_e = cam_opts.dark_current_e_per_s * binning_ * binning_ * exposure_s;
  const float speckle_floor = stripe_max * 1e-3f;
  const int max_dn = frame.max_value();
  // A colour sensor: each pixel behind one filter of the mosaic (red, green, blue: 0, 1, 2 in
  // the pattern's first two rows), passing the pointer's red and the room's white light as
  // CameraOptions says.
  frame.format = PixelFormatOfName(cam_opts.pixel_format);
  const bool mosaic = IsBayer(frame.format);
  const int mx = frame.format == PixelFormat::kBayerGR || frame.format == PixelFormat::kBayerBG;
  const int my = frame.format == PixelFormat::kBayerGB || frame.format == PixelFormat::kBayerBG;
  static constexpr int kFilterAt[2][2] = {{0, 1}, {1, 2}};  // RG / GB, the kBayerRG pattern
  static constexpr float kPointerPass[3] = {0.9f, 0.10f, 0.05f};
  static constexpr float kWhitePass[3] = {0.30f, 0.40f, 0.30f};
  ParallelRows(h, [&](int v_begin, int v_end) {
    for (int v = v_begin; v < v_end; ++v) {
      NoiseSource noise(frame_seed ^ SplitMix64(static_cast<uint64_t>(v)));
      const size_t row = static_cast<size_t>(v) * w;
      for (int u = 0; u < w; ++u) {
        const int filter = mosaic ? kFilterAt[(v + my) & 1][(u + mx) & 1] : -1;
        const float white = mosaic ? kWhitePass[filter] : 1.0f;
        const float red = mosaic ? kPointerPass[filter] : 1.0f;
        double e = ambient_e_per_s_[row + u] * exposure_s * white + dark_e;
        const float s = stripe[row + u] * red;
        if (s > speckle_floor && light.speckle_contrast > 0) {
          e += s * SpeckleFactor(u, v, grain_px, light.speckle_contrast, frame_seed);
        } else {
          e += s;
        }
        if (!glow.empty()) e += glow[row + u] * red;
        if (cam_opts.noise) e = noise.ShotAndRead(e, read_var);
        e = std::min(e, full_well);
        const int dn = std::clamp(static_cast<int>(e * dn_per_e + 0.5), 0, max_dn);
        if (frame.bit_depth > 8) {
          frame.bytes[2 * (row + u)] = static_cast<uint8_t>(dn & 0xFF);
          frame.bytes[2 * (row + u) + 1] = static_cast<uint8_t>(dn >> 8);
        } else {
          frame.bytes[row + u] = static_cast<uint8_t>(dn);
        }
      }
    }
  });
  // The region of interest: the frame's band of rows (the sensor renders as a whole, the
  // camera reads out and sends only the band), in binned rows.
  if (region_rows_ > 0) {
    const int first = region_first_row_ / binning_;
    const int last = std::min(h, (region_first_row_ + region_rows_ + binning_ - 1) / binning_);
    const size_t stride = frame.stride_bytes();
    frame.bytes.erase(frame.bytes.begin() + static_cast<ptrdiff_t>(stride * last),
                      frame.bytes.end());
    frame.bytes.erase(frame.bytes.begin(),
                      frame.bytes.begin() + static_cast<ptrdiff_t>(stride * first));
    frame.offset_y = first;
    frame.height = last - first;
    frame.format = BayerShifted(frame.format, 0, first);
  }
  // The frame then crosses the camera's link: its bytes at the link's rate.
  *link_s_out = LinkSeconds(frame.bytes.size());
  return frame;
}

}  // namespace insitu::sim
