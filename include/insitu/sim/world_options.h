// The simulated world: every physical effect is a named parameter with a realistic default.
// docs/simulator.md says where each default comes from. Frames: the world frame is the galvo
// frame (seed 000 sec. 2.1: world and galvo coordinates coincide): origin at the centre of the
// scan field on the focal plane of the objective (dynamic focus at 0), z up toward the scan
// head, x and y the galvo axes. Lengths in mm, angles in degrees unless a name says otherwise.
//
// These structs are the *truth*. Only the simulator reads them; the reconstruction sees images,
// commands and its own calibration files.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "insitu/core/status.h"
#include "insitu/optics/scan_head.h"

namespace insitu::sim {

// Geometry of a two-mirror scan head with an f-theta (or telecentric) objective.
using ScanOpticsGeometry = optics::HeadGeometry;

struct BeamOptions {
  double wavelength_nm = 680.0;
  double power_mw = 0.15;
  double waist_diameter_mm = 0.4;  // 1/e^2 diameter at the focus
  double m2 = 1.5;                 // beam quality factor
  // How this beam goes through the head against the beam the head was designed for (the
  // marking laser): input misalignment, mrad, and lateral colour, % of image height.
  double offset_x_mrad = 0.0;
  double offset_y_mrad = 0.0;
  double lateral_colour_pct = 0.0;

  optics::BeamPath Path() const { return {offset_x_mrad, offset_y_mrad, lateral_colour_pct}; }
  Status Validate() const;
};

// The scan head's coaxial camera: it looks down through the same mirrors and f-theta objective
// as the beams (a dichroic before the mirrors), so it sees a small field around wherever the
// head points, focused at the dynamic-focus height. Used to inspect marks.
struct CoaxialCameraOptions {
  bool present = true;
  std::string model = "SIM-COAX";
  std::string serial = "SIM-C001";
  int width_px = 1024;
  int height_px = 1024;
  double pixel_on_part_um = 5.0;       // sensor pitch over the magnification, as built
  double rotation_deg = 0.4;           // sensor x against galvo x, as mounted
  double numerical_aperture = 0.027;   // 7 mm aperture radius at 255 mm: defocus blur 2 NA dz
  double psf_sigma_um = 4.3;           // diffraction at 550 nm: 0.21 lambda / NA
  double focus_offset_mm = 0.0;        // sharp image this far above the marking beam's focus
  double illumination_e_per_ms = 8000.0;  // coaxial LED, electrons per ms on a white pixel
  double full_well_e = 10000.0;
  double read_noise_e = 6.0;
  double exposure_ms = 2.0;

  Status Validate() const;
};

// A library effect (fit/effects.h) the simulated head carries: where a command lands moves by
// it, as in measured reality (a model extension from `insitu diagnose`).
struct FieldEffectOption {
  std::string name;
  std::vector<double> params;  // in the effect's parameter order
};

struct ScanHeadOptions {
  ScanOpticsGeometry optics;           // as built (the truth)
  ScanOpticsGeometry design;           // what the head's own correction table assumes
  double x_zero_offset_mrad = 0.0;     // mechanical zero error of the X mirror (optical angle)
  double y_zero_offset_mrad = 0.0;
  double y_mirror_height_mm = 355.0;   // height of the Y-mirror reflection point (seed's point a)
  double field_half_size_mm = 70.0;    // commands beyond +-this are refused
  double focus_range_mm = 25.0;        // dynamic focus travel +-
  double tracking_lag_ms = 0.16;       // first-order lag of the mirrors behind the command
  double clock_us = 10.0;              // list clock
  // Where a mirror settles after a jump differs from the last time by this (rms per axis,
  // optical angle): the galvos' repeatability. Scan heads of the intelliSCAN class quote
  // < 2 urad; at 255 mm that is ~0.5 um on the field.
  double repeatability_urad = 2.0;
  // Resolution of the command the controller sends the head: 20 bits over the field (SL2-100
  // on RTC5/6; 16 for XY2-100 heads such as LMC boards drive): 0.13 um steps on +-70 mm.
  int command_bits = 20;
  // The head's controller corrects the field for its design (a digital head with its own
  // correction table: SL2-100, RTC5/6). false: the galvos take their drive linearly (optical
  // angle = command / design focal length), as an analogue XY2-100 head behind an LMC board
  // does; then the board's uploaded table is all the correction there is.
  bool own_correction = true;
  BeamOptions pointer;                               // red pointer (class 2)
  BeamOptions marking{1064.0, 30000.0, 0.040, 1.3};  // fibre marking laser
  CoaxialCameraOptions coaxial;
  std::vector<FieldEffectOption> field_effects;  // none by default

  Status Validate() const;
};

struct CameraOptions {
  std::string model = "VH-5MG";
  std::string serial = "SIM-0001";
  int width_px = 2448;
  int height_px = 2048;
  double pixel_pitch_um = 3.45;
  double lens_focal_length_mm = 15.0;
  std::string lens = "FV1520";
  std::array<double, 2> principal_point_offset_px{6.0, -4.0};  // from the sensor centre
  double k1 = -0.06, k2 = 0.08, p1 = 0.0002, p2 = -0.0001, k3 = 0.0;  // Brown-Conrady
  std::array<double, 3> position_mm{-182.0, 1.5, 299.0};  // entrance pupil in the world
  std::array<double, 3> look_at_mm{0.6, -0.4, 0.0};       // point on the optical axis
  double roll_deg = 0.3;                                  // about the optical axis
  double f_number = 11.0;
  double quantum_efficiency = 0.42;   // at 680 nm
  double full_well_e = 10000.0;
  double read_noise_e = 8.0;
  double dark_current_e_per_s = 20.0;
  double gain_db = 0.0;
  int bit_depth = 8;                  // 8 or 12
  // "Mono" or a colour sensor's mosaic: "BayerRG", "BayerGR", "BayerGB", "BayerBG". Its
  // filters pass the pointer's red (590-700 nm) at 0.9 (red), 0.10 (green), 0.05 (blue) of
  // the mono sensor's response, and white room light at 0.30, 0.40, 0.30.
  std::string pixel_format = "Mono";
  double exposure_ms = 50.0;          // initial setting; jobs set their own
  bool noise = true;                  // shot, read and dark noise
  // The link a frame travels over after its exposure, MB/s (1e6 bytes): GigE's 125 MB/s less
  // 74 bytes of Ethernet, IP, UDP and GVSP framing per 1500-byte packet (~6 %). A frame of n
  // bytes takes n / link to arrive: the rate falls with the region's size as on a real camera.
  // 0: no link time.
  double link_mb_per_s = 118.0;
  // Its trigger input is wired to the scan head's trigger output: a scan exposes each line on
  // the head's pulse, and the next line starts while the frame crosses the link. A pulse that
  // comes while the camera still exposes is ignored, as on a real camera.
  bool head_trigger = false;

  Status Validate() const;
};

struct LightOptions {
  double ambient_lux = 300.0;        // room light on the part
  double speckle_contrast = 0.2;     // std/mean of the stripe intensity from speckle
  double speckle_grain_px = 0.0;     // 0: from wavelength and f-number (1.22 lambda N)
  bool shadows = true;               // the part blocks the beam and the camera's view
  // A lamp or a window beside the cell: a point source at lamp_position_mm (world, mm) giving
  // lamp_lux on a surface facing it at the world's origin, falling with the square of the
  // distance and the cosine of incidence (no shadows: the lamp lights every face turned to
  // it). Room light on one side of the part, a gradient across the stripe. 0: none.
  std::array<double, 3> lamp_position_mm{-300.0, 0.0, 300.0};
  double lamp_lux = 0.0;
  // The pointer's light scattered once more by the surfaces it lights: a spot's diffuse light
  // falls on every surface facing it (cosines over the squared distance), strongest in a
  // concave corner (a step's foot, a pocket), a glow beside the stripe. Off: one bounce only.
  bool interreflection = false;

  Status Validate() const;
};

struct PartOptions {
  // none | plane | step_gauge | arc | insert | grid_plate | panel
  std::string kind = "step_gauge";
  std::array<double, 2> position_mm{0.0, 0.0};  // centre of the footprint on the stage
  double rotation_deg = 0.0;                    // about z
  double albedo = 0.45;                         // diffuse reflectance at 680 nm
  // A glossy part (machined aluminium ~0.5, stainless ~0.4, a solder-masked board ~0.05): the
  // fraction of the light reflected about the surface normal, in a lobe of specular_lobe_deg
  // (1 sigma: a fine-turned face ~2, bead-blasted ~15). The camera sees a glint where the
  // lobe points at it, and the mirrored beam lights the surface it reaches: a second line.
  double specular = 0.0;
  double specular_lobe_deg = 5.0;
  // Single-pulse ablation threshold of the part's material for the marking laser (ns pulses,
  // 1064 nm; steels 0.5..2 J/cm^2).
  double ablation_threshold_j_per_cm2 = 1.0;
  // What a mark looks like: each pulse removes delta ln(F / F_th) (the logarithmic ablation
  // law; delta is the effective penetration depth), and the ablated surface darkens with
  // depth towards `marked_reflectance` of the bare albedo (oxide and roughness), with
  // 1/e depth `darkening_depth_um`.
  double ablation_depth_um = 0.4;
  double marked_reflectance = 0.25;
  double darkening_depth_um = 3.0;
  // plane: a plate of the given thickness covering the footprint
  double plane_thickness_mm = 2.0;
  std::array<double, 2> plane_size_mm{120.0, 120.0};
  // step_gauge: steps side by side along x, each the full length along y
  double gauge_length_mm = 80.0;
  double gauge_step_width_mm = 5.0;
  std::vector<double> gauge_heights_mm{3.0, 5.0, 10.0, 15.0};
  // arc: cylindrical crown along y over a footprint width (x) x length (y)
  double arc_width_mm = 40.0;
  double arc_length_mm = 40.0;
  double arc_height_mm = 11.5;
  double arc_edge_height_mm = 3.0;
  // insert: equilateral triangle with rounded corners, rake band and a central hole
  // Side of the sharp triangle: 16.14 mm (the seed's vernier L) + 2 (sqrt(3) - 1) 0.2 mm.
  double insert_edge_mm = 16.433;
  double insert_corner_radius_mm = 0.2;
  double insert_thickness_mm = 4.68;
  double insert_hole_diameter_mm = 3.8;
  double insert_rake_deg = 10.0;
  double insert_rake_land_mm = 1.5;
  // grid_plate: a chrome-on-glass reticle (seed 001 sec. 3.3's calibration grid) lying flat on
  // the stage: "+" crosses on a square pitch, centred on the glass, every cross whose bars fit
  // on the glass square. Each bar is grid_plate_cross_mm long (tip to tip) and
  // grid_plate_line_um wide (seed 001: 9 um). The chrome is on the top face, so the top is the
  // surface the cameras see (no refraction through the glass). Reflectance as the coaxial
  // camera sees it under its own (bright-field) light: chrome returns its ~0.6 specular
  // reflectance into the objective; bare glass only its ~4 % Fresnel reflection (the black
  // plate under it scatters diffusely, mostly outside the objective's small aperture):
  // bright crosses on a dark field, contrast ~11:1. Soda-lime reticles are 1.5..3 mm thick
  // (2.3 mm = 0.09 in is the common one).
  double grid_plate_pitch_mm = 1.0;
  double grid_plate_cross_mm = 0.5;
  double grid_plate_line_um = 9.0;
  double grid_plate_size_mm = 14.0;
  double grid_plate_thickness_mm = 2.3;
  double grid_plate_chrome_albedo = 0.55;
  double grid_plate_glass_albedo = 0.05;
  // panel: a clamped aircraft-skin panel under chemical-milling maskant (seed 002's sample: 200
  // x 200 mm of 6061 aluminium under a maskant film, grooves 0.48 mm wide and 0.31 mm deep).
  // The skin is clamped along its two edges at x = -+ size/2 and bows between them: the top
  // rises by panel_bow_mm at the middle, as (1 + cos(2 pi x / size_x)) / 2 (a beam clamped at
  // both ends). `albedo` is the maskant's. The marking laser ablates the maskant by the
  // logarithmic law with its own threshold and depth per pulse; the aluminium under it stops
  // the cut (its threshold is ablation_threshold_j_per_cm2 and depth ablation_depth_um), so a
  // groove cut through the film has the metal as its floor.
  std::array<double, 2> panel_size_mm{200.0, 200.0};
  double panel_thickness_mm = 2.0;       // the aluminium skin
  double maskant_thickness_mm = 0.31;    // the film (seed 002: grooves 0.3124 +- 0.0148 deep)
  double panel_bow_mm = 0.0;             // clamping bend, + up
  // Tooling holes through the skin (the datums a chemical-milling template is pinned to and the
  // inspection locates the part by), centres relative to the panel's centre in its own frame.
  std::vector<std::array<double, 2>> panel_holes_mm{{-50.0, -40.0}, {50.0, -40.0}};
  double panel_hole_diameter_mm = 6.0;
  // Maskant at 1064 nm, ns pulses: an elastomer film (neoprene or styrene-butadiene) loaded with
  // pigment, far below metals' thresholds.
  double maskant_ablation_threshold_j_per_cm2 = 0.15;
  double maskant_ablation_depth_um = 4.0;

  Status Validate() const;
};

struct StageOptions {
  double z_mm = 0.0;              // top of the plate at start
  double min_z_mm = -20.0;
  double max_z_mm = 20.0;
  double speed_mm_per_s = 10.0;
  double plate_albedo = 0.12;     // black anodised aluminium
  double plate_ablation_threshold_j_per_cm2 = 0.5;  // anodised layer, ns pulses at 1064 nm
  // Reflectance of a deep mark relative to the bare plate: ablating the black anodised layer
  // bares the aluminium (diffuse reflectance ~0.5 against 0.12), so marks show light on dark.
  // Same depth law as the part's marked_reflectance.
  double plate_marked_reflectance = 4.0;
  double plate_size_mm = 400.0;
  // The plate's bow (mm): how far the midpoints of its edges stand below its centre (a dome;
  // negative: a dish), its centre at the stage's height. A part
  // rests on it rigidly: on its crown (a dome) or on its footprint's farthest points (a dish),
  // tilted by the slope under its centre. A machined tooling plate is flat to ~0.05 mm over
  // 400 mm; one that was heated unevenly, welded on or dropped bows by a millimetre or more.
  // (A paraboloid: a sphere's cap to within the bow's square over the radius.) The board laid
  // on the plate for field calibration and the profiler's calibration block stand on the
  // stage's plane, not on the bow.
  double plate_bow_mm = 0.0;
  // The stage's travel against its commands (its leadscrew's pitch error), parts per million:
  // commanded z lands at z (1 + scale_error_ppm 1e-6). Its encoder counts the same screw, so
  // the position it reports is the commanded one.
  double scale_error_ppm = 0.0;
  // Labels on the plate: [x, y, width, height, albedo] (mm, world; 0..1), a white sticker or
  // a lit fixture beside the part (paper ~0.8): brighter than the stripe's surface under room
  // light.
  std::vector<std::array<double, 5>> labels;

  Status Validate() const;
};

// A printed chessboard calibration target the operator holds in the field when asked.
// Pose of view k: poses[k] = [x, y, z, rx, ry, rz] (mm, deg): the centre of the board's top
// face in the world and its rotation (about x, then y, then z). Until the operator places it
// (SimWorld::PlaceBoard) the board is out of the way. Corners of the pattern are the inner
// corners of the squares.
struct BoardOptions {
  bool present = false;          // the cell has a board the operator can place
  int inner_cols = 11;           // inner corners along the board's x
  int inner_rows = 8;            // inner corners along the board's y
  double square_mm = 10.0;
  double margin_mm = 8.0;        // light border around the squares
  double albedo_dark = 0.04;     // printed black
  double albedo_light = 0.80;    // white
  std::vector<std::array<double, 6>> poses{{0.0, 0.0, 0.0, 0.0, 0.0, 0.0}};
  // Where the operator lays the board flat on the stage plate when asked (field calibration):
  // [x, y, face height above the plate top, rotation about z] (mm, mm, mm, deg). The printed
  // board on a 2 mm aluminium sheet, laid by hand near the field centre.
  std::array<double, 4> plate_pose{4.0, -3.0, 2.0, 1.5};

  Status Validate() const;
};

// The gantry that carries the line profiler over the stage (seed 002's machine, three linear
// axes and a C axis about the vertical; A stays at 0 on this machine). Its frame is placed in
// the world by `machine_in_world` [x, y, z, rx, ry, rz] (mm, deg): the tool frame at axes zero
// is that frame; moving the axes to (x, y, z, c) puts the tool at machine (x, y, z) turned by c
// about the machine's z.
struct GantryOptions {
  bool present = false;
  std::string model = "SIM-GANTRY";
  std::array<double, 6> machine_in_world{0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  std::array<double, 3> travel_min_mm{-160.0, -160.0, 0.0};
  std::array<double, 3> travel_max_mm{160.0, 160.0, 250.0};
  double c_travel_deg = 360.0;          // C moves in [-c_travel, c_travel]
  double speed_mm_per_s = 200.0;
  double c_speed_deg_per_s = 90.0;
  double settle_ms = 20.0;
  // Where each move really ends against its command (the positioning repeatability, seed 002:
  // <= 0.05 mm after compensation on its five-axis machine; a ground-screw gantry does 2 um).
  double repeatability_um = 2.0;
  double encoder_counts_per_mm = 1000.0;

  Status Validate() const;
};

// A 2D laser line profiler on the gantry's tool (seed 002: an SR7140, 3200 points 25 um apart,
// +-24 um in z). The laser fan comes from `emitter_height_mm` above the middle of the line, the
// camera looks at the line from the sensor's -y side at `triangulation_deg` from the laser
// plane; a point is invalid where the fan cannot reach it or the camera cannot see it (a
// groove's steep flank), where it lies outside the range, or where too little light returns.
// `mount` is the sensor frame in the tool frame [x, y, z, rx, ry, rz] (mm, deg; rotations
// about x, then y, then z): the truth the mounting calibration must find.
struct ProfilerOptions {
  bool present = false;
  std::string model = "SIM-LP3200";
  std::string serial = "SIM-P001";
  int points = 3200;
  double x_spacing_mm = 0.025;
  double z_min_mm = -10.0;
  double z_max_mm = 10.0;
  double emitter_height_mm = 140.0;   // fan source above the reference point
  double triangulation_deg = 25.0;
  double z_resolution_mm = 0.0005;    // one count of the range output (+-10 mm in 40,000)
  double noise_um = 1.5;              // speckle: 1 sigma of one point's range
  double min_signal = 0.02;           // albedo x cos(incidence) under which no line is seen
  double spike_rate = 2e-4;           // points read off a second reflection (per point)
  double spike_max_mm = 0.3;
  double exposure_us = 100.0;
  double max_rate_hz = 5000.0;
  // As built: the machine builder's drawing says [0, -40, -140, 0, 0, 0]; no sensor sits
  // exactly there.
  std::array<double, 6> mount{0.35, -40.2, -139.6, 0.25, -0.15, 0.6};

  Status Validate() const;
};

// The profiler's calibration block (seed 002 eq. 9-10): a truncated square pyramid on a
// square plate, fixed to the stage beside the part where the gantry reaches it and the galvo
// does not (the profiler alone sees it). Its faces are what a CMM report gives the mounting
// calibration.
struct CalibrationBlockOptions {
  bool present = false;
  std::array<double, 2> position_mm{150.0, 0.0};  // the pyramid's axis on the stage, world xy
  double rotation_deg = 0.0;                      // about z
  double plate_thickness_mm = 10.0;               // the plate's top above the stage plate
  double plate_mm = 80.0;                         // the plate's side
  double base_mm = 60.0;                          // the pyramid's base side
  double top_mm = 30.0;                           // its top's side
  double height_mm = 15.0;                        // above the plate

  Status Validate() const;
};

// Device faults the simulated machine injects (for the daemon's fault handling): each fires
// once its count is reached; -1 never. Counted per machine (per job).
struct FaultOptions {
  int camera_timeout_at_frame = -1;   // that frame grab times out (no frame arrives)
  int camera_drop_frame_at = -1;      // that frame loses packets: the stream reports it
  int camera_corrupt_frame_at = -1;   // that frame arrives with a truncated payload
  int scanner_error_at_command = -1;  // that scanner command (pointer line or list) fails
  bool stage_stuck = false;           // every stage move fails to arrive
  int profiler_stop_at_profile = -1;  // from that profile on, the line profiler sends nothing

  Status Validate() const;
};

struct WorldOptions {
  std::string name = "default";
  ScanHeadOptions scan_head;
  CameraOptions camera;
  LightOptions light;
  PartOptions part;
  StageOptions stage;
  BoardOptions board;
  FaultOptions faults;
  GantryOptions gantry;
  ProfilerOptions profiler;
  CalibrationBlockOptions block;
  uint64_t seed = 1;
  // Virtual seconds per wall-clock second: 0 runs as fast as the computer can (tests, CI);
  // 1 runs the devices in real time, as a daemon driving a real cell would see them.
  double real_time_factor = 0.0;

  Status Validate() const;
};

}  // namespace insitu::sim
