#include "insitu/sim/world_options.h"

#include <cmath>

#include "insitu/core/validate.h"
#include "insitu/fit/extension.h"

namespace insitu::sim {

Status BeamOptions::Validate() const {
  if (!IsPositiveFinite(wavelength_nm)) return InvalidValue("wavelength_nm", "> 0", wavelength_nm);
  if (!(power_mw >= 0.0)) return InvalidValue("power_mw", ">= 0", power_mw);
  if (!IsPositiveFinite(waist_diameter_mm))
    return InvalidValue("waist_diameter_mm", "> 0", waist_diameter_mm);
  if (!(m2 >= 1.0)) return InvalidValue("m2", ">= 1", m2);
  return Path().Validate();
}

Status ScanHeadOptions::Validate() const {
  INSITU_RETURN_IF_ERROR(optics.Validate().Prefixed("optics"));
  INSITU_RETURN_IF_ERROR(design.Validate().Prefixed("design"));
  INSITU_RETURN_IF_ERROR(pointer.Validate().Prefixed("pointer"));
  INSITU_RETURN_IF_ERROR(marking.Validate().Prefixed("marking"));
  INSITU_RETURN_IF_ERROR(coaxial.Validate().Prefixed("coaxial"));
  {
    std::vector<fit::EffectParams> effects;
    for (const FieldEffectOption& e : field_effects) effects.push_back({e.name, e.params});
    const auto ext = fit::ModelExtension::Make(effects);
    if (!ext.ok()) return ext.status().Prefixed("field_effects");
  }
  if (!IsPositiveFinite(field_half_size_mm))
    return InvalidValue("field_half_size_mm", "> 0", field_half_size_mm);
  if (!(repeatability_urad >= 0 && repeatability_urad <= 1000)) {
    return InvalidValue("repeatability_urad", "in [0, 1000]", repeatability_urad);
  }
  if (command_bits < 12 || command_bits > 24)
    return InvalidValue("command_bits", "in 12..24", command_bits);
  if (!(focus_range_mm >= 0.0)) return InvalidValue("focus_range_mm", ">= 0", focus_range_mm);
  if (!(tracking_lag_ms >= 0.0 && tracking_lag_ms < 100.0)) {
    return InvalidValue("tracking_lag_ms", "in [0, 100)", tracking_lag_ms);
  }
  if (!IsPositiveFinite(clock_us)) return InvalidValue("clock_us", "> 0", clock_us);
  if (!IsPositiveFinite(y_mirror_height_mm))
    return InvalidValue("y_mirror_height_mm", "> 0", y_mirror_height_mm);
  return Status::Ok();
}

Status CoaxialCameraOptions::Validate() const {
  if (width_px < 16 || width_px > 8192) return InvalidValue("width_px", "in [16, 8192]", width_px);
  if (height_px < 16 || height_px > 8192)
    return InvalidValue("height_px", "in [16, 8192]", height_px);
  if (!(pixel_on_part_um > 0.1 && pixel_on_part_um < 1000)) {
    return InvalidValue("pixel_on_part_um", "in (0.1, 1000)", pixel_on_part_um);
  }
  if (!(numerical_aperture > 0 && numerical_aperture < 1)) {
    return InvalidValue("numerical_aperture", "in (0, 1)", numerical_aperture);
  }
  if (!(psf_sigma_um >= 0)) return InvalidValue("psf_sigma_um", ">= 0", psf_sigma_um);
  if (!(illumination_e_per_ms >= 0))
    return InvalidValue("illumination_e_per_ms", ">= 0", illumination_e_per_ms);
  if (!IsPositiveFinite(full_well_e)) return InvalidValue("full_well_e", "> 0", full_well_e);
  if (!(read_noise_e >= 0)) return InvalidValue("read_noise_e", ">= 0", read_noise_e);
  if (!IsPositiveFinite(exposure_ms)) return InvalidValue("exposure_ms", "> 0", exposure_ms);
  return Status::Ok();
}

Status CameraOptions::Validate() const {
  if (width_px < 16 || width_px > 16384)
    return InvalidValue("width_px", "in [16, 16384]", width_px);
  if (height_px < 16 || height_px > 16384)
    return InvalidValue("height_px", "in [16, 16384]", height_px);
  if (!IsPositiveFinite(pixel_pitch_um))
    return InvalidValue("pixel_pitch_um", "> 0", pixel_pitch_um);
  if (!IsPositiveFinite(lens_focal_length_mm)) {
    return InvalidValue("lens_focal_length_mm", "> 0", lens_focal_length_mm);
  }
  for (double k : {k1, k2, p1, p2, k3}) {
    if (!std::isfinite(k) || std::abs(k) > 10.0)
      return InvalidValue("k1", "distortion in [-10, 10]", k);
  }
  if (!(f_number >= 0.7 && f_number <= 64))
    return InvalidValue("f_number", "in [0.7, 64]", f_number);
  if (!(quantum_efficiency > 0 && quantum_efficiency <= 1)) {
    return InvalidValue("quantum_efficiency", "in (0, 1]", quantum_efficiency);
  }
  if (!IsPositiveFinite(full_well_e)) return InvalidValue("full_well_e", "> 0", full_well_e);
  if (!(read_noise_e >= 0)) return InvalidValue("read_noise_e", ">= 0", read_noise_e);
  if (!(dark_current_e_per_s >= 0))
    return InvalidValue("dark_current_e_per_s", ">= 0", dark_current_e_per_s);
  if (!(gain_db >= 0 && gain_db <= 24)) return InvalidValue("gain_db", "in [0, 24]", gain_db);
  if (bit_depth != 8 && bit_depth != 12) return InvalidValue("bit_depth", "8 or 12", bit_depth);
  if (pixel_format != "Mono" && pixel_format != "BayerRG" && pixel_format != "BayerGR" &&
      pixel_format != "BayerGB" && pixel_format != "BayerBG") {
    return InvalidArgument("pixel_format must be Mono, BayerRG, BayerGR, BayerGB or BayerBG, got " +
                           pixel_format);
  }
  if (!(link_mb_per_s >= 0.0 && link_mb_per_s <= 1e5)) {
    return InvalidValue("link_mb_per_s", "in [0, 1e5] (0: no link time)", link_mb_per_s);
  }
  if (!(exposure_ms > 0 && exposure_ms <= 10000)) {
    return InvalidValue("exposure_ms", "in (0, 10000]", exposure_ms);
  }
  const double dx = look_at_mm[0] - position_mm[0], dy = look_at_mm[1] - position_mm[1],
               dz = look_at_mm[2] - position_mm[2];
  if (std::sqrt(dx * dx + dy * dy + dz * dz) < 1.0) {
    return InvalidArgument("look_at_mm must differ from position_mm");
  }
  return Status::Ok();
}

Status LightOptions::Validate() const {
  if (!(ambient_lux >= 0 && ambient_lux < 2e5))
    return InvalidValue("ambient_lux", "in [0, 2e5)", ambient_lux);
  if (!(speckle_contrast >= 0 && speckle_contrast <= 1)) {
    return InvalidValue("speckle_contrast", "in [0, 1]", speckle_contrast);
  }
  if (!(lamp_lux >= 0 && lamp_lux < 2e5)) return InvalidValue("lamp_lux", "in [0, 2e5)", lamp_lux);
  for (double c : lamp_position_mm) {
    if (!std::isfinite(c)) return InvalidValue("lamp_position_mm", "finite", c);
  }
  if (lamp_lux > 0 &&
      std::hypot(lamp_position_mm[0], lamp_position_mm[1], lamp_position_mm[2]) < 50.0) {
    return InvalidArgument("lamp_position_mm must be at least 50 mm from the world's origin");
  }
  if (!(speckle_grain_px >= 0 && speckle_grain_px < 100)) {
    return InvalidValue("speckle_grain_px", "in [0, 100)", speckle_grain_px);
  }
  return Status::Ok();
}

Status PartOptions::Validate() const {
  if (kind != "none" && kind != "plane" && kind != "step_gauge" && kind != "arc" &&
      kind != "insert" && kind != "grid_plate" && kind != "panel") {
    return InvalidArgument(
        "kind must be one of none, plane, step_gauge, arc, insert, grid_plate, panel, got " +
        kind);
  }
  if (!(specular >= 0 && specular <= 1)) return InvalidValue("specular", "in [0, 1]", specular);
  if (!(albedo + specular <= 1.0 + 1e-9)) {
    return InvalidArgument("albedo + specular must be at most 1 (energy), got " +
                           std::to_string(albedo + specular));
  }
  if (!(specular_lobe_deg >= 0.5 && specular_lobe_deg <= 45)) {
    return InvalidValue("specular_lobe_deg", "in [0.5, 45]", specular_lobe_deg);
  }
  if (!(albedo >= 0 && albedo <= 1)) return InvalidValue("albedo", "in [0, 1]", albedo);
  if (!(ablation_depth_um >= 0))
    return InvalidValue("ablation_depth_um", ">= 0", ablation_depth_um);
  if (!(marked_reflectance >= 0 && marked_reflectance <= 1)) {
    return InvalidValue("marked_reflectance", "in [0, 1]", marked_reflectance);
  }
  if (!IsPositiveFinite(darkening_depth_um))
    return InvalidValue("darkening_depth_um", "> 0", darkening_depth_um);
  if (!IsPositiveFinite(plane_thickness_mm))
    return InvalidValue("plane_thickness_mm", "> 0", plane_thickness_mm);
  if (!IsPositiveFinite(gauge_length_mm))
    return InvalidValue("gauge_length_mm", "> 0", gauge_length_mm);
  if (!IsPositiveFinite(gauge_step_width_mm))
    return InvalidValue("gauge_step_width_mm", "> 0", gauge_step_width_mm);
  if (gauge_heights_mm.empty()) return InvalidArgument("gauge_heights_mm must not be empty");
  for (double hgt : gauge_heights_mm) {
    if (!IsPositiveFinite(hgt)) return InvalidValue("gauge_heights_mm", "all > 0", hgt);
  }
  if (!(arc_edge_height_mm > 0 && arc_height_mm > arc_edge_height_mm)) {
    return InvalidValue("arc_height_mm", "> arc_edge_height_mm > 0", arc_height_mm);
  }
  if (!IsPositiveFinite(insert_edge_mm))
    return InvalidValue("insert_edge_mm", "> 0", insert_edge_mm);
  if (!(insert_hole_diameter_mm >= 0 && insert_hole_diameter_mm < insert_edge_mm / 2)) {
    return InvalidValue("insert_hole_diameter_mm", "in [0, edge/2)", insert_hole_diameter_mm);
  }
  if (!IsPositiveFinite(grid_plate_pitch_mm))
    return InvalidValue("grid_plate_pitch_mm", "> 0", grid_plate_pitch_mm);
  if (!IsPositiveFinite(grid_plate_line_um))
    return InvalidValue("grid_plate_line_um", "> 0", grid_plate_line_um);
  // Crosses stand apart (a bar as long as the pitch would make a ruled grid) and are more
  // than a blob of line.
  if (!(grid_plate_cross_mm > 2e-3 * grid_plate_line_um &&
        grid_plate_cross_mm < grid_plate_pitch_mm)) {
    return InvalidValue("grid_plate_cross_mm", "in (2 line widths, grid_plate_pitch_mm)",
                        grid_plate_cross_mm);
  }
  if (!(grid_plate_size_mm >= grid_plate_cross_mm && grid_plate_size_mm <= 1000)) {
    return InvalidValue("grid_plate_size_mm", "in [grid_plate_cross_mm, 1000]", grid_plate_size_mm);
  }
  if (!IsPositiveFinite(grid_plate_thickness_mm)) {
    return InvalidValue("grid_plate_thickness_mm", "> 0", grid_plate_thickness_mm);
  }
  if (!(grid_plate_chrome_albedo >= 0 && grid_plate_chrome_albedo <= 1)) {
    return InvalidValue("grid_plate_chrome_albedo", "in [0, 1]", grid_plate_chrome_albedo);
  }
  if (!(grid_plate_glass_albedo >= 0 && grid_plate_glass_albedo <= 1)) {
    return InvalidValue("grid_plate_glass_albedo", "in [0, 1]", grid_plate_glass_albedo);
  }
  for (double s : panel_size_mm) {
    if (!(s > 1 && s <= 2000)) return InvalidValue("panel_size_mm", "each in (1, 2000]", s);
  }
  if (!IsPositiveFinite(panel_thickness_mm))
    return InvalidValue("panel_thickness_mm", "> 0", panel_thickness_mm);
  if (!(maskant_thickness_mm >= 0 && maskant_thickness_mm < 5))
    return InvalidValue("maskant_thickness_mm", "in [0, 5)", maskant_thickness_mm);
  if (!(std::abs(panel_bow_mm) < 0.05 * panel_size_mm[0])) {
    return InvalidValue("panel_bow_mm", "within 5 % of the panel's x size", panel_bow_mm);
  }
  if (!(panel_hole_diameter_mm > 0 && panel_hole_diameter_mm < 100))
    return InvalidValue("panel_hole_diameter_mm", "in (0, 100)", panel_hole_diameter_mm);
  for (const auto& h : panel_holes_mm) {
    if (!(std::abs(h[0]) + 0.5 * panel_hole_diameter_mm < 0.5 * panel_size_mm[0] &&
          std::abs(h[1]) + 0.5 * panel_hole_diameter_mm < 0.5 * panel_size_mm[1])) {
      return InvalidValue("panel_holes_mm", "holes inside the panel", h[0]);
    }
  }
  if (!IsPositiveFinite(maskant_ablation_threshold_j_per_cm2)) {
    return InvalidValue("maskant_ablation_threshold_j_per_cm2", "> 0",
                        maskant_ablation_threshold_j_per_cm2);
  }
  if (!(maskant_ablation_depth_um >= 0))
    return InvalidValue("maskant_ablation_depth_um", ">= 0", maskant_ablation_depth_um);
  return Status::Ok();
}

Status GantryOptions::Validate() const {
  for (int k = 0; k < 3; ++k) {
    if (!(std::isfinite(travel_min_mm[k]) && travel_min_mm[k] < travel_max_mm[k] &&
          std::isfinite(travel_max_mm[k]))) {
      return InvalidValue("travel_min_mm", "< travel_max_mm on every axis", travel_min_mm[k]);
    }
  }
  for (double v : machine_in_world) {
    if (!std::isfinite(v)) return InvalidValue("machine_in_world", "finite", v);
  }
  if (!(c_travel_deg >= 0 && c_travel_deg <= 720))
    return InvalidValue("c_travel_deg", "in [0, 720]", c_travel_deg);
  if (!IsPositiveFinite(speed_mm_per_s)) return InvalidValue("speed_mm_per_s", "> 0", speed_mm_per_s);
  if (!IsPositiveFinite(c_speed_deg_per_s))
    return InvalidValue("c_speed_deg_per_s", "> 0", c_speed_deg_per_s);
  if (!(settle_ms >= 0 && settle_ms < 1e4)) return InvalidValue("settle_ms", "in [0, 1e4)", settle_ms);
  if (!(repeatability_um >= 0 && repeatability_um < 1000))
    return InvalidValue("repeatability_um", "in [0, 1000)", repeatability_um);
  if (!(encoder_counts_per_mm >= 1 && encoder_counts_per_mm <= 1e6))
    return InvalidValue("encoder_counts_per_mm", "in [1, 1e6]", encoder_counts_per_mm);
  return Status::Ok();
}

Status CalibrationBlockOptions::Validate() const {
  if (!(std::isfinite(position_mm[0]) && std::isfinite(position_mm[1])))
    return InvalidValue("position_mm", "finite", position_mm[0]);
  if (!std::isfinite(rotation_deg)) return InvalidValue("rotation_deg", "finite", rotation_deg);
  if (!IsPositiveFinite(plate_thickness_mm))
    return InvalidValue("plate_thickness_mm", "> 0", plate_thickness_mm);
  if (!(top_mm > 0 && base_mm > top_mm && plate_mm > base_mm && plate_mm < 1000)) {
    return InvalidValue("base_mm", "between top_mm (> 0) and plate_mm (< 1000)", base_mm);
  }
  if (!IsPositiveFinite(height_mm)) return InvalidValue("height_mm", "> 0", height_mm);
  return Status::Ok();
}

Status ProfilerOptions::Validate() const {
  if (points < 16 || points > 16384) return InvalidValue("points", "in [16, 16384]", points);
  if (!(x_spacing_mm > 1e-4 && x_spacing_mm < 10))
    return InvalidValue("x_spacing_mm", "in (1e-4, 10)", x_spacing_mm);
  if (!(z_min_mm < z_max_mm && std::isfinite(z_min_mm) && std::isfinite(z_max_mm)))
    return InvalidValue("z_min_mm", "< z_max_mm", z_min_mm);
  if (!(emitter_height_mm > z_max_mm)) {
    return InvalidValue("emitter_height_mm", "above the range's top (z_max_mm)", emitter_height_mm);
  }
  if (!(triangulation_deg > 1 && triangulation_deg < 80))
    return InvalidValue("triangulation_deg", "in (1, 80)", triangulation_deg);
  if (!(z_resolution_mm > 0 && z_resolution_mm < 0.1))
    return InvalidValue("z_resolution_mm", "in (0, 0.1)", z_resolution_mm);
  // Coord3D_C16 carries the range in 65535 counts.
  if ((z_max_mm - z_min_mm) / z_resolution_mm > 65534) {
    return InvalidValue("z_resolution_mm", "at least the range / 65534 (16-bit output)",
                        z_resolution_mm);
  }
  if (!(noise_um >= 0 && noise_um < 1000)) return InvalidValue("noise_um", "in [0, 1000)", noise_um);
  if (!(min_signal >= 0 && min_signal < 1)) return InvalidValue("min_signal", "in [0, 1)", min_signal);
  if (!(spike_rate >= 0 && spike_rate < 0.5)) return InvalidValue("spike_rate", "in [0, 0.5)", spike_rate);
  if (!(spike_max_mm >= 0)) return InvalidValue("spike_max_mm", ">= 0", spike_max_mm);
  if (!(exposure_us >= 1 && exposure_us <= 1e5))
    return InvalidValue("exposure_us", "in [1, 1e5]", exposure_us);
  if (!IsPositiveFinite(max_rate_hz)) return InvalidValue("max_rate_hz", "> 0", max_rate_hz);
  for (double v : mount) {
    if (!std::isfinite(v)) return InvalidValue("mount", "finite", v);
  }
  return Status::Ok();
}

Status StageOptions::Validate() const {
  if (!(min_z_mm < max_z_mm)) return InvalidValue("min_z_mm", "< max_z_mm", min_z_mm);
  if (!(z_mm >= min_z_mm && z_mm <= max_z_mm))
    return InvalidValue("z_mm", "within the travel", z_mm);
  if (!IsPositiveFinite(speed_mm_per_s))
    return InvalidValue("speed_mm_per_s", "> 0", speed_mm_per_s);
  if (!(plate_albedo >= 0 && plate_albedo <= 1))
    return InvalidValue("plate_albedo", "in [0, 1]", plate_albedo);
  if (!(plate_marked_reflectance >= 0 && plate_marked_reflectance * plate_albedo <= 1)) {
    return InvalidValue("plate_marked_reflectance", "in [0, 1 / plate_albedo]",
                        plate_marked_reflectance);
  }
  if (!IsPositiveFinite(plate_size_mm)) return InvalidValue("plate_size_mm", "> 0", plate_size_mm);
  // A bow of 1 % of the plate's size slopes its edges by 0.04: far past any plate a part could
  // stand on, and where the plate's intersection (Scene) still converges in its four passes.
  if (!(std::abs(plate_bow_mm) <= 0.01 * plate_size_mm)) {
    return InvalidValue("plate_bow_mm", "within +-1 % of plate_size_mm", plate_bow_mm);
  }
  for (size_t i = 0; i < labels.size(); ++i) {
    const auto& l = labels[i];
    const std::string name = "labels[" + std::to_string(i) + "]";
    if (!std::isfinite(l[0]) || !std::isfinite(l[1]) || !IsPositiveFinite(l[2]) ||
        !IsPositiveFinite(l[3])) {
      return InvalidArgument(name + " must be [x, y, width > 0, height > 0, albedo]");
    }
    if (!(l[4] >= 0 && l[4] <= 1)) return InvalidValue(name + " albedo", "in [0, 1]", l[4]);
  }
  if (!(std::abs(scale_error_ppm) <= 1e5)) {
    return InvalidValue("scale_error_ppm", "within +-100000", scale_error_ppm);
  }
  return Status::Ok();
}

Status BoardOptions::Validate() const {
  if (inner_cols < 3 || inner_rows < 3)
    return InvalidValue("inner_cols", ">= 3 (and inner_rows)", inner_cols);
  if (!IsPositiveFinite(square_mm)) return InvalidValue("square_mm", "> 0", square_mm);
  if (!(margin_mm >= 0)) return InvalidValue("margin_mm", ">= 0", margin_mm);
  if (!(albedo_dark >= 0 && albedo_light <= 1 && albedo_dark < albedo_light)) {
    return InvalidValue("albedo_dark", "in [0, albedo_light)", albedo_dark);
  }
  if (poses.empty()) return InvalidArgument("poses must list at least one pose");
  for (double v : plate_pose) {
    if (!std::isfinite(v)) return InvalidArgument("plate_pose must be finite numbers");
  }
  if (!(plate_pose[2] >= 0 && plate_pose[2] < 50)) {
    return InvalidValue("plate_pose", "a height above the plate in [0, 50) mm", plate_pose[2]);
  }
  for (const auto& p : poses) {
    for (double v : p) {
      if (!std::isfinite(v)) return InvalidArgument("poses must be finite numbers");
    }
  }
  return Status::Ok();
}

Status WorldOptions::Validate() const {
  INSITU_RETURN_IF_ERROR(scan_head.Validate().Prefixed("scan_head"));
  INSITU_RETURN_IF_ERROR(camera.Validate().Prefixed("camera"));
  INSITU_RETURN_IF_ERROR(light.Validate().Prefixed("light"));
  INSITU_RETURN_IF_ERROR(part.Validate().Prefixed("part"));
  INSITU_RETURN_IF_ERROR(stage.Validate().Prefixed("stage"));
  INSITU_RETURN_IF_ERROR(board.Validate().Prefixed("board"));
  INSITU_RETURN_IF_ERROR(faults.Validate().Prefixed("faults"));
  INSITU_RETURN_IF_ERROR(gantry.Validate().Prefixed("gantry"));
  INSITU_RETURN_IF_ERROR(profiler.Validate().Prefixed("profiler"));
  INSITU_RETURN_IF_ERROR(block.Validate().Prefixed("block"));
  if (profiler.present && !gantry.present) {
    return InvalidArgument("profiler: present needs a gantry to carry it (gantry.present)");
  }
  if (!(real_time_factor == 0 || (real_time_factor >= 1e-3 && real_time_factor <= 1000))) {
    return InvalidValue("real_time_factor", "0 (as fast as possible) or in [0.001, 1000]",
                        real_time_factor);
  }
  return Status::Ok();
}

Status FaultOptions::Validate() const {
  if (camera_timeout_at_frame < -1)
    return InvalidValue("camera_timeout_at_frame", ">= -1", camera_timeout_at_frame);
  if (camera_drop_frame_at < -1)
    return InvalidValue("camera_drop_frame_at", ">= -1", camera_drop_frame_at);
  if (camera_corrupt_frame_at < -1) {
    return InvalidValue("camera_corrupt_frame_at", ">= -1", camera_corrupt_frame_at);
  }
  if (scanner_error_at_command < -1) {
    return InvalidValue("scanner_error_at_command", ">= -1", scanner_error_at_command);
  }
  if (profiler_stop_at_profile < -1) {
    return InvalidValue("profiler_stop_at_profile", ">= -1", profiler_stop_at_profile);
  }
  return Status::Ok();
}

}  // namespace insitu::sim
