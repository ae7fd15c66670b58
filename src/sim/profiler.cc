// The gantry and the line profiler it carries: each profile is ray-cast on the surface the
// profiler would see (the part's top less what the marking laser ablated), with the sensor's
// own triangulation geometry: the laser fan from its emitter, the camera at the triangulation
// angle, a point invalid where either cannot reach it, too little light returns, or it lies
// outside the range; speckle noise and the odd second-reflection spike on the rest.
#include <algorithm>
#include <cmath>
#include <random>

#include "insitu/sim/world.h"
#include "mark_map.h"

namespace insitu::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;

// [x, y, z, rx, ry, rz] (mm, deg; rotations about x, then y, then z) as a rigid transform.
Eigen::Isometry3d PoseOf(const std::array<double, 6>& p) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(Eigen::Vector3d(p[0], p[1], p[2]));
  t.rotate(Eigen::AngleAxisd(p[5] * kDeg, Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(p[4] * kDeg, Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(p[3] * kDeg, Eigen::Vector3d::UnitX()));
  return t;
}

}  // namespace

Status SimWorld::MoveGantry(const std::array<double, 4>& xyzc) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const GantryOptions& g = options_.gantry;
  if (!g.present) return FailedPrecondition("the machine has no gantry");
  const char* names[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    // The same thousandth of slack as hw::CheckTravel: a position read back and sent again.
    if (!(xyzc[k] >= g.travel_min_mm[k] - 1e-3 && xyzc[k] <= g.travel_max_mm[k] + 1e-3)) {
      return OutOfRange(std::string("gantry ") + names[k] + " " + std::to_string(xyzc[k]) +
                        " mm is outside its travel [" + std::to_string(g.travel_min_mm[k]) +
                        ", " + std::to_string(g.travel_max_mm[k]) + "]");
    }
  }
  if (!(std::abs(xyzc[3]) <= g.c_travel_deg + 1e-3)) {
    return OutOfRange("gantry c " + std::to_string(xyzc[3]) + " deg is outside its travel +-" +
                      std::to_string(g.c_travel_deg));
  }
  double dist = 0.0;
  for (int k = 0; k < 3; ++k) dist = std::max(dist, std::abs(xyzc[k] - gantry_command_[k]));
  const double dc = std::abs(xyzc[3] - gantry_command_[3]);
  const double moving = std::max(dist / g.speed_mm_per_s, dc / g.c_speed_deg_per_s);
  gantry_command_ = xyzc;
  // Repeatability is quoted as a +-2 sigma band about the command; C repeats to the same
  // arc at 100 mm radius.
  std::normal_distribution<double> n(0.0, 0.5e-3 * g.repeatability_um);
  for (int k = 0; k < 3; ++k) gantry_true_[k] = xyzc[k] + n(profiler_rng_);
  gantry_true_[3] = xyzc[3] + n(profiler_rng_) / 100.0 / kDeg;
  if (moving > 0) now_s_ += moving + 1e-3 * g.settle_ms;
  PaceTo(now_s_);
  return Status::Ok();
}

// The encoders read the commanded position: a servo holds its encoder on the command, and the
// repeatability is where the tool really ends up, which no encoder on the screw sees.
std::array<double, 4> SimWorld::gantry_position() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return gantry_command_;
}

Status SimWorld::SetProfilerExposure(double exposure_us) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  if (!(exposure_us >= 1 && exposure_us <= 1e5)) {
    return OutOfRange("profiler exposure " + std::to_string(exposure_us) +
                      " us is outside [1, 100000]");
  }
  profiler_exposure_us_ = exposure_us;
  return Status::Ok();
}

Eigen::Isometry3d SimWorld::TrueSensorInWorld() const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  Eigen::Isometry3d tool = PoseOf(options_.gantry.machine_in_world);
  tool.translate(Eigen::Vector3d(gantry_true_[0], gantry_true_[1], gantry_true_[2]));
  tool.rotate(Eigen::AngleAxisd(gantry_true_[3] * kDeg, Eigen::Vector3d::UnitZ()));
  return tool * PoseOf(options_.profiler.mount);
}

double SimWorld::AblatedDepthMm(double x_mm, double y_mm) const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return 1e-3 * marks_->DepthUm(x_mm, y_mm);
}

double SimWorld::TrueSurfaceZ(double x_mm, double y_mm) const {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  return SurfaceZ(x_mm, y_mm);
}

double SimWorld::SurfaceZ(double x_mm, double y_mm) const {
  const double part =
      scene_->stage_z() + scene_->TrueHeightAt(x_mm, y_mm) - 1e-3 * marks_->DepthUm(x_mm, y_mm);
  const CalibrationBlockOptions& b = options_.block;
  if (!b.present) return part;
  // The block in its own frame: u, v from its axis.
  const double c = block_cos_, s = block_sin_;
  const double dx = x_mm - b.position_mm[0], dy = y_mm - b.position_mm[1];
  const double u = c * dx + s * dy, v = -s * dx + c * dy;
  const double m = std::max(std::abs(u), std::abs(v));
  if (m > 0.5 * b.plate_mm) return part;
  const double ramp = (0.5 * b.base_mm - m) / (0.5 * (b.base_mm - b.top_mm));
  const double top = b.plate_thickness_mm + b.height_mm * std::clamp(ramp, 0.0, 1.0);
  return std::max(part, scene_->stage_z() + top);
}

bool SimWorld::SurfaceBlocks(const Eigen::Vector3d& from, const Eigen::Vector3d& to) const {
  const Eigen::Vector3d d = to - from;
  const double horizontal = std::hypot(d.x(), d.y());
  if (!(d.z() > 0)) return true;  // a light or a camera below the surface
  // Where the segment is clear for good: above the part's top near a wall, else a little
  // above the deepest groove around.
  // Near a wall a segment may pass under: the part's, or the block's (taller) near the block.
  const CalibrationBlockOptions& b = options_.block;
  const double block_top = b.present ? b.plate_thickness_mm + b.height_mm : 0.0;
  const double block_reach = (block_top + 1.0) * horizontal / d.z() + 1.0;
  const bool near_block =
      b.present && std::hypot(from.x() - b.position_mm[0], from.y() - b.position_mm[1]) <
                       0.75 * b.plate_mm + block_reach;
  const double tallest = near_block ? std::max(scene_->part_top_above_stage(), block_top)
                                    : scene_->part_top_above_stage();
  const double reach = (tallest + 1.0) * horizontal / d.z() + 1.0;
  const bool near_edge = near_block || scene_->DistanceToPartEdge(from.x(), from.y()) < reach;
  const bool near_marks = marks_->MarkedNear(from.x(), from.y(), 1.0);
  if (!near_edge && !near_marks) return false;  // a smooth, gently curved top hides nothing
  // Marks only lower the surface: beside them the segment is clear once above the part's
  // unmarked top there.
  const double clear_z = near_edge ? scene_->stage_z() + tallest + 0.01
                                   : scene_->stage_z() + scene_->TrueHeightAt(from.x(), from.y()) +
                                         1e-3;
  // 5 um steps along the horizontal: under the grooves' and the cells' scale.
  const double step = horizontal > 0 ? std::min(1.0, 0.005 / horizontal) : 1.0;
  for (double s = step; s <= 1.0; s += step) {
    const Eigen::Vector3d p = from + s * d;
    if (p.z() >= clear_z) return false;
    if (p.z() < SurfaceZ(p.x(), p.y()) - 1e-4) return true;
  }
  return false;
}

Result<SimWorld::ProfileShot> SimWorld::GrabProfile() {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const ProfilerOptions& o = options_.profiler;
  if (!o.present) return FailedPrecondition("the machine has no line profiler");
  const Eigen::Isometry3d s = TrueSensorInWorld();
  const Eigen::Vector3d emitter = s * Eigen::Vector3d(0.0, 0.0, o.emitter_height_mm);
  const double th = o.triangulation_deg * kDeg;
  const Eigen::Vector3d camera =
      s * Eigen::Vector3d(0.0, -o.emitter_height_mm * std::sin(th),
                          o.emitter_height_mm * std::cos(th));
  const Eigen::Vector3d axis = s.linear() * Eigen::Vector3d::UnitZ();  // sensor z in the world
  ProfileShot shot;
  shot.z_mm.assign(static_cast<size_t>(o.points), std::numeric_limits<float>::quiet_NaN());
  std::normal_distribution<double> speckle(0.0, 1e-3 * o.noise_um);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double x0 = -0.5 * (o.points - 1) * o.x_spacing_mm;
  for (int i = 0; i < o.points; ++i) {
    const Eigen::Vector3d base = s * Eigen::Vector3d(x0 + i * o.x_spacing_mm, 0.0, 0.0);
    // The surface along the sensor's z through this point: Newton on
    // f(z) = (base + z axis).z - surface(xy), the line all but vertical.
    const auto f = [&](double z) {
      const Eigen::Vector3d p = base + z * axis;
      return p.z() - SurfaceZ(p.x(), p.y());
    };
    double z = o.z_max_mm;
    if (!(f(z) > 0)) continue;  // the surface above the range's top
    bool found = false;
    for (int it = 0; it < 8; ++it) {
      const double fz = f(z);
      if (std::abs(fz) < 1e-6) {
        found = true;
        break;
      }
      z -= fz / axis.z();
    }
    if (!found) {
      // A wall under the line: march down to the first crossing, then bisect.
      double hi = o.z_max_mm, lo = hi;
      for (lo = hi - 0.02; lo >= o.z_min_mm - 0.02; lo -= 0.02) {
        if (f(lo) <= 0) break;
        hi = lo;
      }
      if (f(lo) > 0) continue;
      for (int it = 0; it < 40; ++it) {
        const double mid = 0.5 * (lo + hi);
        (f(mid) > 0 ? hi : lo) = mid;
      }
      z = 0.5 * (lo + hi);
    }
    if (z < o.z_min_mm || z > o.z_max_mm) continue;
    const Eigen::Vector3d p = base + z * axis;
    // Light returned: albedo x cos(incidence) from the fan, the camera on the lit side. Away
    // from marks, walls and the block the top is smooth and all but level (a clamping bow
    // tilts it by a few hundredths): its normal is taken as up, and nothing can hide it.
    // Near: within a wall's height (plus margin) of it, farther than the fan (+-16 deg) or the
    // camera (25 deg) can look past one.
    const double wall_reach = scene_->part_top_above_stage() + 3.0;
    const double block_reach =
        options_.block.plate_thickness_mm + options_.block.height_mm + 3.0;
    const bool rough = marks_->MarkedNear(p.x(), p.y(), 1.0) ||
                       scene_->DistanceToPartEdge(p.x(), p.y()) < wall_reach ||
                       (options_.block.present &&
                        std::hypot(p.x() - options_.block.position_mm[0],
                                   p.y() - options_.block.position_mm[1]) <
                            0.75 * options_.block.plate_mm + block_reach);
    const double e = 0.005;
    const Eigen::Vector3d normal =
        rough ? Eigen::Vector3d(
                    -(SurfaceZ(p.x() + e, p.y()) - SurfaceZ(p.x() - e, p.y())) / (2 * e),
                    -(SurfaceZ(p.x(), p.y() + e) - SurfaceZ(p.x(), p.y() - e)) / (2 * e),
                    1.0)
                    .normalized()
              : Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d to_light = (emitter - p).normalized(), to_camera = (camera - p).normalized();
    const bool on_part = scene_->OnPart(p.x(), p.y());
    const double albedo =
        (on_part ? scene_->PartAlbedoAt(p.x(), p.y()) : scene_->PlateAlbedoAt(p.x(), p.y())) *
        MarkFactor(p.x(), p.y(), 0.0, on_part);
    if (albedo * normal.dot(to_light) < o.min_signal || normal.dot(to_camera) <= 0.02) continue;
    if (rough && (SurfaceBlocks(p, emitter) || SurfaceBlocks(p, camera))) continue;
    double reading = z + speckle(profiler_rng_);
    if (o.spike_rate > 0 && unit(profiler_rng_) < o.spike_rate) {
      reading += o.spike_max_mm * (2.0 * unit(profiler_rng_) - 1.0);
    }
    reading = std::round(reading / o.z_resolution_mm) * o.z_resolution_mm;
    if (reading < o.z_min_mm || reading > o.z_max_mm) continue;
    shot.z_mm[static_cast<size_t>(i)] = static_cast<float>(reading);
  }
  now_s_ += std::max(1e-6 * profiler_exposure_us_, 1.0 / o.max_rate_hz);
  shot.t_s = now_s_;
  shot.sequence = profile_counter_++;
  shot.encoder = std::llround(gantry_command_[1] * options_.gantry.encoder_counts_per_mm);
  PaceTo(now_s_);
  return shot;
}

}  // namespace insitu::sim
