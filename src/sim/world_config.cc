#include "insitu/sim/world_config.h"

#include <string>
#include <vector>

namespace insitu::sim {

namespace {

void ReadOptics(ConfigReader& r, ScanOpticsGeometry* g) {
  r.Read("focal_length_mm", &g->focal_length_mm);
  r.Read("mirror_separation_mm", &g->mirror_separation_mm);
  r.Read("exit_pupil_height_mm", &g->exit_pupil_height_mm);
  r.Read("pupil_aberration", &g->pupil_aberration);
  r.Read("telecentric", &g->telecentric);
  r.Read("ftheta_c3", &g->ftheta_c3);
  r.Read("ftheta_c5", &g->ftheta_c5);
  r.Read("x_axis_tilt_mrad", &g->x_axis_tilt_mrad);
  r.Read("y_axis_tilt_mrad", &g->y_axis_tilt_mrad);
  if (r.ok()) r.FailFromValidate(g->Validate());
}

void ReadBeam(ConfigReader& r, BeamOptions* b) {
  r.Read("wavelength_nm", &b->wavelength_nm);
  r.Read("power_mw", &b->power_mw);
  r.Read("waist_diameter_mm", &b->waist_diameter_mm);
  r.Read("m2", &b->m2);
  r.Read("offset_x_mrad", &b->offset_x_mrad);
  r.Read("offset_y_mrad", &b->offset_y_mrad);
  r.Read("lateral_colour_pct", &b->lateral_colour_pct);
  if (r.ok()) r.FailFromValidate(b->Validate());
}

}  // namespace

void ReadWorld(ConfigReader& r, WorldOptions* w) {
  r.Skip("base");  // merged when the job was loaded
  r.Read("name", &w->name);
  r.Read("real_time_factor", &w->real_time_factor);
  int seed = static_cast<int>(w->seed);
  r.Read("seed", &seed);
  if (seed < 0) r.Fail("seed", "must be >= 0");
  w->seed = static_cast<uint64_t>(seed);

  ConfigReader& sh = r.Section("scan_head");
  ReadOptics(sh.Section("optics"), &w->scan_head.optics);
  ReadOptics(sh.Section("design"), &w->scan_head.design);
  sh.Read("x_zero_offset_mrad", &w->scan_head.x_zero_offset_mrad);
  sh.Read("y_zero_offset_mrad", &w->scan_head.y_zero_offset_mrad);
  sh.Read("y_mirror_height_mm", &w->scan_head.y_mirror_height_mm);
  sh.Read("field_half_size_mm", &w->scan_head.field_half_size_mm);
  sh.Read("focus_range_mm", &w->scan_head.focus_range_mm);
  sh.Read("tracking_lag_ms", &w->scan_head.tracking_lag_ms);
  sh.Read("clock_us", &w->scan_head.clock_us);
  sh.Read("repeatability_urad", &w->scan_head.repeatability_urad);
  sh.Read("command_bits", &w->scan_head.command_bits);
  sh.Read("own_correction", &w->scan_head.own_correction);
  ReadBeam(sh.Section("pointer"), &w->scan_head.pointer);
  ReadBeam(sh.Section("marking"), &w->scan_head.marking);
  {
    ConfigReader& cx = sh.Section("coaxial");
    CoaxialCameraOptions& o = w->scan_head.coaxial;
    cx.Read("present", &o.present);
    cx.Read("model", &o.model);
    cx.Read("serial", &o.serial);
    cx.Read("width_px", &o.width_px);
    cx.Read("height_px", &o.height_px);
    cx.Read("pixel_on_part_um", &o.pixel_on_part_um);
    cx.Read("rotation_deg", &o.rotation_deg);
    cx.Read("numerical_aperture", &o.numerical_aperture);
    cx.Read("psf_sigma_um", &o.psf_sigma_um);
    cx.Read("focus_offset_mm", &o.focus_offset_mm);
    cx.Read("illumination_e_per_ms", &o.illumination_e_per_ms);
    cx.Read("full_well_e", &o.full_well_e);
    cx.Read("read_noise_e", &o.read_noise_e);
    cx.Read("exposure_ms", &o.exposure_ms);
  }
  if (sh.Has("field_effects")) {
    // Library effects the simulated head carries: [{name: ..., params: [...]}, ...].
    sh.Skip("field_effects");
    const ConfigNode list = sh.node().Child("field_effects");
    w->scan_head.field_effects.clear();
    if (!list.IsSequence()) {
      sh.Fail("field_effects", "must be a list of {name, params}");
    } else {
      for (size_t i = 0; i < list.size() && sh.ok(); ++i) {
        ConfigReader e(list.At(i));
        FieldEffectOption f;
        e.Require("name");
        e.Require("params");
        e.Read("name", &f.name);
        e.Read("params", &f.params);
        const Status st = e.Finish();
        if (!st.ok()) sh.Fail("field_effects", st.message());
        w->scan_head.field_effects.push_back(f);
      }
    }
  }
  if (sh.ok()) sh.FailFromValidate(w->scan_head.Validate());

  ConfigReader& c = r.Section("camera");
  CameraOptions& co = w->camera;
  c.Read("model", &co.model);
  c.Read("serial", &co.serial);
  c.Read("lens", &co.lens);
  c.Read("width_px", &co.width_px);
  c.Read("height_px", &co.height_px);
  c.Read("pixel_pitch_um", &co.pixel_pitch_um);
  c.Read("lens_focal_length_mm", &co.lens_focal_length_mm);
  c.ReadArray("principal_point_offset_px", co.principal_point_offset_px.data(), 2);
  c.Read("k1", &co.k1);
  c.Read("k2", &co.k2);
  c.Read("p1", &co.p1);
  c.Read("p2", &co.p2);
  c.Read("k3", &co.k3);
  c.ReadArray("position_mm", co.position_mm.data(), 3);
  c.ReadArray("look_at_mm", co.look_at_mm.data(), 3);
  c.Read("roll_deg", &co.roll_deg);
  c.Read("f_number", &co.f_number);
  c.Read("quantum_efficiency", &co.quantum_efficiency);
  c.Read("full_well_e", &co.full_well_e);
  c.Read("read_noise_e", &co.read_noise_e);
  c.Read("dark_current_e_per_s", &co.dark_current_e_per_s);
  c.Read("gain_db", &co.gain_db);
  c.Read("bit_depth", &co.bit_depth);
  c.ReadEnum("pixel_format", &co.pixel_format,
             {"Mono", "BayerRG", "BayerGR", "BayerGB", "BayerBG"});
  c.Read("exposure_ms", &co.exposure_ms);
  c.Read("noise", &co.noise);
  c.Read("link_mb_per_s", &co.link_mb_per_s);
  c.Read("head_trigger", &co.head_trigger);
  if (c.ok()) c.FailFromValidate(co.Validate());

  ConfigReader& l = r.Section("light");
  l.Read("ambient_lux", &w->light.ambient_lux);
  l.Read("speckle_contrast", &w->light.speckle_contrast);
  l.Read("speckle_grain_px", &w->light.speckle_grain_px);
  l.Read("shadows", &w->light.shadows);
  l.ReadArray("lamp_position_mm", w->light.lamp_position_mm.data(), 3);
  l.Read("lamp_lux", &w->light.lamp_lux);
  l.Read("interreflection", &w->light.interreflection);
  if (l.ok()) l.FailFromValidate(w->light.Validate());

  ConfigReader& p = r.Section("part");
  PartOptions& po = w->part;
  p.ReadEnum("kind", &po.kind,
             {"none", "plane", "step_gauge", "arc", "insert", "grid_plate", "panel"});
  p.ReadArray("position_mm", po.position_mm.data(), 2);
  p.Read("rotation_deg", &po.rotation_deg);
  p.Read("albedo", &po.albedo);
  p.Read("specular", &po.specular);
  p.Read("specular_lobe_deg", &po.specular_lobe_deg);
  p.Read("ablation_threshold_j_per_cm2", &po.ablation_threshold_j_per_cm2);
  p.Read("ablation_depth_um", &po.ablation_depth_um);
  p.Read("marked_reflectance", &po.marked_reflectance);
  p.Read("darkening_depth_um", &po.darkening_depth_um);
  p.Read("plane_thickness_mm", &po.plane_thickness_mm);
  p.ReadArray("plane_size_mm", po.plane_size_mm.data(), 2);
  p.Read("gauge_length_mm", &po.gauge_length_mm);
  p.Read("gauge_step_width_mm", &po.gauge_step_width_mm);
  p.Read("gauge_heights_mm", &po.gauge_heights_mm);
  p.Read("arc_width_mm", &po.arc_width_mm);
  p.Read("arc_length_mm", &po.arc_length_mm);
  p.Read("arc_height_mm", &po.arc_height_mm);
  p.Read("arc_edge_height_mm", &po.arc_edge_height_mm);
  p.Read("insert_edge_mm", &po.insert_edge_mm);
  p.Read("insert_corner_radius_mm", &po.insert_corner_radius_mm);
  p.Read("insert_thickness_mm", &po.insert_thickness_mm);
  p.Read("insert_hole_diameter_mm", &po.insert_hole_diameter_mm);
  p.Read("insert_rake_deg", &po.insert_rake_deg);
  p.Read("insert_rake_land_mm", &po.insert_rake_land_mm);
  p.Read("grid_plate_pitch_mm", &po.grid_plate_pitch_mm);
  p.Read("grid_plate_cross_mm", &po.grid_plate_cross_mm);
  p.Read("grid_plate_line_um", &po.grid_plate_line_um);
  p.Read("grid_plate_size_mm", &po.grid_plate_size_mm);
  p.Read("grid_plate_thickness_mm", &po.grid_plate_thickness_mm);
  p.Read("grid_plate_chrome_albedo", &po.grid_plate_chrome_albedo);
  p.Read("grid_plate_glass_albedo", &po.grid_plate_glass_albedo);
  p.ReadArray("panel_size_mm", po.panel_size_mm.data(), 2);
  p.Read("panel_thickness_mm", &po.panel_thickness_mm);
  p.Read("maskant_thickness_mm", &po.maskant_thickness_mm);
  p.Read("panel_bow_mm", &po.panel_bow_mm);
  if (p.Has("panel_holes_mm")) {
    p.Skip("panel_holes_mm");
    const ConfigNode holes = p.node().Child("panel_holes_mm");
    po.panel_holes_mm.clear();
    for (size_t i = 0; holes.IsSequence() && i < holes.size(); ++i) {
      auto h = holes.At(i).AsDoubleList();
      if (!h.ok() || h->size() != 2) {
        p.Fail("panel_holes_mm", "entry " + std::to_string(i) + " must be [x, y]");
        break;
      }
      po.panel_holes_mm.push_back({(*h)[0], (*h)[1]});
    }
    if (!holes.IsSequence()) p.Fail("panel_holes_mm", "must be a list of [x, y]");
  }
  p.Read("panel_hole_diameter_mm", &po.panel_hole_diameter_mm);
  p.Read("maskant_ablation_threshold_j_per_cm2", &po.maskant_ablation_threshold_j_per_cm2);
  p.Read("maskant_ablation_depth_um", &po.maskant_ablation_depth_um);
  if (p.ok()) p.FailFromValidate(po.Validate());

  ConfigReader& st = r.Section("stage");
  st.Read("z_mm", &w->stage.z_mm);
  st.Read("min_z_mm", &w->stage.min_z_mm);
  st.Read("max_z_mm", &w->stage.max_z_mm);
  st.Read("speed_mm_per_s", &w->stage.speed_mm_per_s);
  st.Read("plate_albedo", &w->stage.plate_albedo);
  st.Read("plate_ablation_threshold_j_per_cm2", &w->stage.plate_ablation_threshold_j_per_cm2);
  st.Read("plate_marked_reflectance", &w->stage.plate_marked_reflectance);
  st.Read("plate_size_mm", &w->stage.plate_size_mm);
  st.Read("plate_bow_mm", &w->stage.plate_bow_mm);
  if (st.Has("labels")) {
    st.Skip("labels");
    const ConfigNode labels = st.node().Child("labels");
    w->stage.labels.clear();
    for (size_t i = 0; labels.IsSequence() && i < labels.size(); ++i) {
      auto l = labels.At(i).AsDoubleList();
      if (!l.ok() || l->size() != 5) {
        st.Fail("labels", "entry " + std::to_string(i) + " must be [x, y, width, height, albedo]");
        break;
      }
      w->stage.labels.push_back({(*l)[0], (*l)[1], (*l)[2], (*l)[3], (*l)[4]});
    }
    if (!labels.IsSequence()) st.Fail("labels", "must be a list of [x, y, width, height, albedo]");
  }
  st.Read("scale_error_ppm", &w->stage.scale_error_ppm);
  if (st.ok()) st.FailFromValidate(w->stage.Validate());

  ConfigReader& g = r.Section("gantry");
  GantryOptions& go = w->gantry;
  g.Read("present", &go.present);
  g.Read("model", &go.model);
  g.ReadArray("machine_in_world", go.machine_in_world.data(), 6);
  g.ReadArray("travel_min_mm", go.travel_min_mm.data(), 3);
  g.ReadArray("travel_max_mm", go.travel_max_mm.data(), 3);
  g.Read("c_travel_deg", &go.c_travel_deg);
  g.Read("speed_mm_per_s", &go.speed_mm_per_s);
  g.Read("c_speed_deg_per_s", &go.c_speed_deg_per_s);
  g.Read("settle_ms", &go.settle_ms);
  g.Read("repeatability_um", &go.repeatability_um);
  g.Read("encoder_counts_per_mm", &go.encoder_counts_per_mm);
  if (g.ok()) g.FailFromValidate(go.Validate());

  ConfigReader& pr = r.Section("profiler");
  ProfilerOptions& pf = w->profiler;
  pr.Read("present", &pf.present);
  pr.Read("model", &pf.model);
  pr.Read("serial", &pf.serial);
  pr.Read("points", &pf.points);
  pr.Read("x_spacing_mm", &pf.x_spacing_mm);
  pr.Read("z_min_mm", &pf.z_min_mm);
  pr.Read("z_max_mm", &pf.z_max_mm);
  pr.Read("emitter_height_mm", &pf.emitter_height_mm);
  pr.Read("triangulation_deg", &pf.triangulation_deg);
  pr.Read("z_resolution_mm", &pf.z_resolution_mm);
  pr.Read("noise_um", &pf.noise_um);
  pr.Read("min_signal", &pf.min_signal);
  pr.Read("spike_rate", &pf.spike_rate);
  pr.Read("spike_max_mm", &pf.spike_max_mm);
  pr.Read("exposure_us", &pf.exposure_us);
  pr.Read("max_rate_hz", &pf.max_rate_hz);
  pr.ReadArray("mount", pf.mount.data(), 6);
  if (pr.ok()) pr.FailFromValidate(pf.Validate());

  ConfigReader& bl = r.Section("block");
  CalibrationBlockOptions& bk = w->block;
  bl.Read("present", &bk.present);
  bl.ReadArray("position_mm", bk.position_mm.data(), 2);
  bl.Read("rotation_deg", &bk.rotation_deg);
  bl.Read("plate_thickness_mm", &bk.plate_thickness_mm);
  bl.Read("plate_mm", &bk.plate_mm);
  bl.Read("base_mm", &bk.base_mm);
  bl.Read("top_mm", &bk.top_mm);
  bl.Read("height_mm", &bk.height_mm);
  if (bl.ok()) bl.FailFromValidate(bk.Validate());

  ConfigReader& fa = r.Section("faults");
  fa.Read("camera_timeout_at_frame", &w->faults.camera_timeout_at_frame);
  fa.Read("camera_drop_frame_at", &w->faults.camera_drop_frame_at);
  fa.Read("camera_corrupt_frame_at", &w->faults.camera_corrupt_frame_at);
  fa.Read("scanner_error_at_command", &w->faults.scanner_error_at_command);
  fa.Read("stage_stuck", &w->faults.stage_stuck);
  fa.Read("profiler_stop_at_profile", &w->faults.profiler_stop_at_profile);
  if (fa.ok()) fa.FailFromValidate(w->faults.Validate());
  ConfigReader& b = r.Section("board");
  BoardOptions& bo = w->board;
  b.Read("present", &bo.present);
  b.Read("inner_cols", &bo.inner_cols);
  b.Read("inner_rows", &bo.inner_rows);
  b.Read("square_mm", &bo.square_mm);
  b.Read("margin_mm", &bo.margin_mm);
  b.Read("albedo_dark", &bo.albedo_dark);
  b.Read("albedo_light", &bo.albedo_light);
  b.ReadArray("plate_pose", bo.plate_pose.data(), 4);
  if (b.Has("poses")) {
    b.Skip("poses");
    const ConfigNode poses = b.node().Child("poses");
    bo.poses.clear();
    for (size_t i = 0; poses.IsSequence() && i < poses.size(); ++i) {
      auto pose = poses.At(i).AsDoubleList();
      if (!pose.ok() || pose->size() != 6) {
        b.Fail("poses", "entry " + std::to_string(i) + " must be [x, y, z, rx, ry, rz]");
        break;
      }
      bo.poses.push_back({(*pose)[0], (*pose)[1], (*pose)[2], (*pose)[3], (*pose)[4], (*pose)[5]});
    }
    if (!poses.IsSequence()) b.Fail("poses", "must be a list of [x, y, z, rx, ry, rz]");
  }
  if (b.ok()) b.FailFromValidate(bo.Validate());
}

}  // namespace insitu::sim
