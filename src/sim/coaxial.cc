// The scan head's coaxial camera. It looks back down the beam path, so its
// field is centred on where the chief ray meets the surface for the mirrors'
// current angles, and it is sharp at the dynamic-focus height. Over its few-mm
// field the chief rays stay within a degree of the centre ray: the image is the
// surface seen along that ray, scaled by pixel_on_part_um and turned by the
// sensor's mounting rotation. The picture is the surface's reflectance under
// the coaxial light (part or plate albedo, a reticle's pattern averaged over
// each pixel's footprint, times what the marks left of it),
// blurred per pixel by diffraction and by defocus (a disc of diameter 2 NA dz,
// sigma NA dz / 2), then shot and read noise and 8-bit quantisation.
#include <algorithm>
#include <cmath>
#include <vector>

#include "insitu/sim/world.h"
#include "sim/mark_map.h"
#include "sim/noise.h"
#include "sim/parallel.h"

namespace insitu::sim {
namespace {

// Height from which beam rays are traced down (above any part).
constexpr double kStartAboveStageMm = 200.0;

// Separable Gaussian blur of a w x h float image, sigma in pixels (0: copy).
// Clamped edges. Hand-written: the simulator carries no image library, and
// these kernels are a few pixels.
std::vector<float> Blur(const std::vector<float>& in, int w, int h, double sigma) {
  if (sigma < 0.05) return in;
  const int r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  std::vector<float> k(2 * r + 1);
  double sum = 0.0;
  for (int i = -r; i <= r; ++i)
    sum += k[i + r] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (float& v : k) v = static_cast<float>(v / sum);
  std::vector<float> tmp(in.size()), out(in.size());
  ParallelRows(h, [&](int v0, int v1) {
    for (int y = v0; y < v1; ++y) {
      for (int x = 0; x < w; ++x) {
        float acc = 0.0f;
        for (int i = -r; i <= r; ++i)
          acc += k[i + r] * in[static_cast<size_t>(y) * w + std::clamp(x + i, 0, w - 1)];
        tmp[static_cast<size_t>(y) * w + x] = acc;
      }
    }
  });
  ParallelRows(h, [&](int v0, int v1) {
    for (int y = v0; y < v1; ++y) {
      for (int x = 0; x < w; ++x) {
        float acc = 0.0f;
        for (int i = -r; i <= r; ++i)
          acc += k[i + r] * tmp[static_cast<size_t>(std::clamp(y + i, 0, h - 1)) * w + x];
        out[static_cast<size_t>(y) * w + x] = acc;
      }
    }
  });
  return out;
}

}  // namespace

Result<Frame> SimWorld::GrabCoaxial(double exposure_us) {
  std::lock_guard<std::recursive_mutex> lock(mutex_);
  const CoaxialCameraOptions& o = options_.scan_head.coaxial;
  if (!o.present) return FailedPrecondition("this scan head has no coaxial camera");
  if (!(exposure_us >= 10.0 && exposure_us <= 1e6)) {
    return OutOfRange("coaxial exposure " + std::to_string(exposure_us) +
                      " us is outside the camera's range [10, 1e6] us");
  }
  const int w = o.width_px, h = o.height_px;
  const ChiefRay ray = true_optics_->Trace(rest_angles_);
  const Eigen::Vector3d start = ray.AtHeight(scene_->stage_z() + kStartAboveStageMm);
  Hit centre;
  std::vector<float> reflectance(static_cast<size_t>(w) * h, 0.0f);
  std::vector<float> defocus_px(reflectance.size(),
                                0.0f);  // blur sigma from defocus, pixels
  const double px_mm = o.pixel_on_part_um * 1e-3;
  const double c = std::cos(o.rotation_deg * M_PI / 180.0),
               s = std::sin(o.rotation_deg * M_PI / 180.0);
  const double focus_z = last_command_.z() + o.focus_offset_mm;
  const Eigen::Vector2d slope = ray.up.head<2>() / ray.up.z();  // xy shift per mm of height
  if (scene_->Intersect(start, -ray.up, 5000.0, &centre)) {
    const Eigen::Vector2d c_xy = centre.point_in_world.head<2>();
    const double plate_z = scene_->stage_z();
    ParallelRows(h, [&](int v0, int v1) {
      for (int v = v0; v < v1; ++v) {
        for (int u = 0; u < w; ++u) {
          // Sensor x along galvo +x, rows down the image along galvo -y (seen
          // from above).
          const double du = (u - 0.5 * (w - 1)) * px_mm, dv = -(v - 0.5 * (h - 1)) * px_mm;
          Eigen::Vector2d p = c_xy + Eigen::Vector2d(c * du - s * dv, s * du + c * dv);
          double top = scene_->TrueHeightAt(p.x(), p.y());
          // Along the (slightly slanted) ray: one correction for the height
          // difference.
          p += slope * (top - (centre.point_in_world.z() - plate_z));
          top = scene_->TrueHeightAt(p.x(), p.y());
          const bool on_part = scene_->OnPart(p.x(), p.y());
          // The part's reflectance over the pixel's footprint (a reticle's 9 um lines are
          // under two pixels wide: sampling their centres would put them on the pixel grid;
          // the triangle of one pixel's half-width: scene.h).
          const double albedo = on_part ? scene_->PartAlbedoAt(p.x(), p.y(), px_mm)
                                        : scene_->PlateAlbedoAt(p.x(), p.y());
          const size_t i = static_cast<size_t>(v) * w + u;
          reflectance[i] = static_cast<float>(albedo * MarkFactor(p.x(), p.y(), 0.5 * px_mm, on_part));
          const double dz = std::abs(focus_z - (plate_z + top)) / ray.up.z();
          defocus_px[i] = static_cast<float>(0.5 * o.numerical_aperture * dz / px_mm);
        }
      }
    });
  }
  // Blur per pixel: the image at a ladder of blur levels, each pixel
  // interpolated between the two levels around its own sigma (diffraction and
  // defocus add in quadrature).
  const double psf_px = o.psf_sigma_um * 1e-3 / px_mm;
  const float max_defocus = *std::max_element(defocus_px.begin(), defocus_px.end());
  const double max_sigma = std::min(std::hypot(psf_px, max_defocus), 40.0);
  std::vector<double> levels{psf_px};
  while (levels.back() < max_sigma) levels.push_back(levels.back() * 1.25 + 0.25);
  std::vector<std::vector<float>> blurred;
  for (double sigma : levels) blurred.push_back(Blur(reflectance, w, h, sigma));

  Frame frame;
  frame.width = w;
  frame.height = h;
  frame.bit_depth = 8;
  frame.bytes.resize(static_cast<size_t>(w) * h);
  frame.sequence = frame_counter_++;
  frame.timestamp_s = now_s_;
  frame.exposure_us = exposure_us;
  const double white_e = o.illumination_e_per_ms * exposure_us * 1e-3;
  const double dn_per_e = 255.0 / o.full_well_e;
  const double read_var = o.read_noise_e * o.read_noise_e;
  const uint64_t seed = SplitMix64(options_.seed * 0xD1B54A32D192ED03ull + frame.sequence);
  ParallelRows(h, [&](int v0, int v1) {
    for (int v = v0; v < v1; ++v) {
      NoiseSource noise(seed ^ SplitMix64(static_cast<uint64_t>(v)));
      for (int u = 0; u < w; ++u) {
        const size_t i = static_cast<size_t>(v) * w + u;
        const double sigma = std::hypot(psf_px, static_cast<double>(defocus_px[i]));
        size_t k = 0;
        while (k + 1 < levels.size() && levels[k + 1] < sigma) ++k;
        double r = blurred[k][i];
        if (k + 1 < levels.size()) {
          const double a = std::clamp((sigma - levels[k]) / (levels[k + 1] - levels[k]), 0.0, 1.0);
          r = (1.0 - a) * r + a * blurred[k + 1][i];
        }
        const double e = std::min(noise.ShotAndRead(r * white_e, read_var), o.full_well_e);
        frame.bytes[i] =
            static_cast<uint8_t>(std::clamp(static_cast<int>(e * dn_per_e + 0.5), 0, 255));
      }
    }
  });
  now_s_ += exposure_us * 1e-6;
  PaceTo(now_s_);
  return frame;
}

}  // namespace insitu::sim
