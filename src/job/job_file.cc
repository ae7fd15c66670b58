#include "insitu/job/job_file.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "insitu/sim/world_config.h"

namespace insitu::job {
namespace fs = std::filesystem;

std::string ResolvePath(const std::string& folder, const std::string& path) {
  if (path.empty() || fs::path(path).is_absolute()) return path;
  return (fs::path(folder) / path).lexically_normal().string();
}

namespace {

// The rest of loading, once the document is read: world, world_changes, --set, the kind.
Result<LoadedJob> Expand(LoadedJob job, const std::vector<std::string>& sets) {
  const std::string& path = job.path;
  if (!job.root.IsMap()) return ParseError(path + ": a job file is a YAML map with a 'job:' key");
  // `--set world=FILE` names another world file: it must replace the job's before the world is
  // read (the other --set keys apply after it, on top of whichever world file is used).
  for (const std::string& s : sets) {
    if (s.rfind("world=", 0) == 0) INSITU_RETURN_IF_ERROR(job.root.Set("world", s.substr(6)));
  }
  const ConfigNode world = job.root.Child("world");
  if (world.IsDefined()) {
    if (!world.IsScalar()) {
      return InvalidArgument(world.Where() + ": expected the name of a world file");
    }
    INSITU_ASSIGN_OR_RETURN(std::string file, world.AsString());
    const std::string world_path = ResolvePath(job.folder, file);
    auto loaded = ConfigNode::LoadFile(world_path);
    if (!loaded.ok()) return loaded.status().Prefixed(world.Where());
    job.world = *loaded;
    // A world file may name a `base:` world (relative to its own folder) and give only what
    // differs from it.
    const ConfigNode base = job.world.Child("base");
    if (base.IsDefined()) {
      INSITU_ASSIGN_OR_RETURN(std::string base_file, base.AsString());
      auto base_world = ConfigNode::LoadFile(
          ResolvePath(fs::path(world_path).parent_path().string(), base_file));
      if (!base_world.ok()) return base_world.status().Prefixed(base.Where());
      if (base_world->Child("base").IsDefined()) {
        return InvalidArgument(base.Where() + ": a base world cannot name a base of its own");
      }
      INSITU_RETURN_IF_ERROR(base_world->Merge(job.world));
      job.world = *base_world;
    }
  }
  // What differs from the world file for this job (simulator only): typically the part the
  // operator put on the stage and where.
  const ConfigNode changes = job.root.Child("world_changes");
  if (changes.IsDefined()) {
    if (!changes.IsMap())
      return InvalidArgument(changes.Where() + ": expected a map of world keys");
    if (!job.world.IsDefined()) {
      return InvalidArgument(changes.Where() + ": the job names no world: file to change");
    }
    INSITU_RETURN_IF_ERROR(job.world.Merge(changes));
  }
  for (const std::string& s : sets) {
    const size_t eq = s.find('=');
    if (eq == std::string::npos || eq == 0) {
      return InvalidArgument("--set '" + s + "': expected dotted.key=value");
    }
    const std::string key = s.substr(0, eq), value = s.substr(eq + 1);
    if (key == "world") continue;  // applied above
    if (key.rfind("world.", 0) == 0) {
      if (!job.world.IsDefined()) {
        return InvalidArgument("--set " + key + ": the job names no world file");
      }
      INSITU_RETURN_IF_ERROR(job.world.Set(key.substr(6), value));
    } else {
      INSITU_RETURN_IF_ERROR(job.root.Set(key, value));
    }
  }
  const ConfigNode kind = job.root.Child("job");
  if (!kind.IsDefined())
    return InvalidArgument(path + ": missing 'job:' (the job kind, e.g. scan)");
  INSITU_ASSIGN_OR_RETURN(job.kind, kind.AsString());
  return job;
}

}  // namespace

Result<LoadedJob> LoadJobFile(const std::string& path, const std::vector<std::string>& sets) {
  LoadedJob job;
  job.path = path;
  job.folder = fs::path(path).parent_path().string();
  if (job.folder.empty()) job.folder = ".";
  INSITU_ASSIGN_OR_RETURN(job.root, ConfigNode::LoadFile(path));
  return Expand(std::move(job), sets);
}

Result<LoadedJob> LoadJobText(const std::string& text, const std::string& origin,
                              const std::string& folder, const std::vector<std::string>& sets) {
  LoadedJob job;
  job.path = origin;
  job.folder = folder.empty() ? "." : folder;
  INSITU_ASSIGN_OR_RETURN(job.root, ConfigNode::Parse(text, origin));
  return Expand(std::move(job), sets);
}

void ReadStripeOptions(ConfigReader& r, vision::StripeOptions* o) {
  std::string direction = "auto";
  r.ReadEnum("direction", &direction, {"auto", "columns", "rows"});
  o->direction = direction == "columns" ? vision::StripeDirection::kColumns
                 : direction == "rows"  ? vision::StripeDirection::kRows
                                        : vision::StripeDirection::kAuto;
  r.Read("threshold_ratio", &o->threshold_ratio);
  r.Read("median_kernel", &o->median_kernel);
  r.Read("min_peak", &o->min_peak);
  r.Read("min_contrast", &o->min_contrast);
  r.Read("max_width_px", &o->max_width_px);
  r.Read("min_peak_separation_px", &o->min_peak_separation_px);
  r.Read("second_peak_ratio", &o->second_peak_ratio);
  r.Read("saturation_level", &o->saturation_level);
  r.Read("expected_width_px", &o->expected_width_px);
  std::string channel = "red";
  r.ReadEnum("colour_channel", &channel, {"red", "green", "blue"});
  o->colour_channel = channel == "green"  ? vision::ColourChannel::kGreen
                      : channel == "blue" ? vision::ColourChannel::kBlue
                                          : vision::ColourChannel::kRed;
  if (r.ok()) r.FailFromValidate(o->Validate());
}

namespace {

// A 16-bit word as hardware documents write them: 0x9588, or decimal.
void ReadWord(ConfigReader& r, const std::string& key, uint16_t* out) {
  if (!r.Has(key)) return;
  std::string text;
  r.Read(key, &text);
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 0);
  if (text.empty() || end == nullptr || *end != '\0' || v < 0 || v > 0xFFFF) {
    r.Fail(key, "'" + text + "' is not a 16-bit word (0x0000..0xFFFF)");
    return;
  }
  *out = static_cast<uint16_t>(v);
}

// A list of 16-bit words (numbers, as the board takes them), exactly as many as `out`.
void ReadWords(ConfigReader& r, const std::string& key, const std::vector<uint16_t*>& out) {
  if (!r.Has(key)) return;
  std::vector<double> values;
  r.Read(key, &values);
  if (!r.ok()) return;
  if (values.size() != out.size()) {
    r.Fail(key,
           "takes " + std::to_string(out.size()) + " words, got " + std::to_string(values.size()));
    return;
  }
  for (size_t i = 0; i < values.size(); ++i) {
    const double v = values[i];
    if (!(v >= 0 && v <= 0xFFFF && v == std::floor(v))) {
      char text[32];
      std::snprintf(text, sizeof text, "%g", v);
      r.Fail(key, std::string(text) + " is not a 16-bit word (0..65535)");
      return;
    }
    *out[i] = static_cast<uint16_t>(v);
  }
}

}  // namespace

void ReadMachine(ConfigReader& root, const std::string& folder, MachineSpec* spec) {
  ConfigReader& m = root.Section("machine");
  hw::MachineConfig& c = spec->config;
  m.Read("backend", &c.backend);
  m.Require("calibration");
  std::string calibration;
  m.Read("calibration", &calibration);
  spec->calibration_path = ResolvePath(folder, calibration);
  // The device of each role (hw/cell.h): not named, the simulator's on a simulated cell and
  // none on a real one.
  m.ReadEnum("scanner", &c.scanner, {"sim", "lmc", "none"});
  m.ReadEnum("camera", &c.camera, {"sim", "aravis", "none"});
  m.ReadEnum("coaxial", &c.coaxial, {"sim", "none"});
  m.ReadEnum("stage", &c.stage, {"sim", "grbl", "none"});
  m.ReadEnum("axis", &c.axis, {"sim", "none"});
  m.ReadEnum("profiler", &c.profiler, {"sim", "aravis", "none"});
  m.ReadEnum("operator", &c.person, {"sim", "person", "none"});
  if (m.Has("grbl")) {
    ConfigReader& g = m.Section("grbl");
    hw::grbl::StageOptions& o = c.grbl;
    g.Read("port", &o.port);
    g.Read("baud", &o.baud);
    std::string axis(1, o.axis);
    g.ReadEnum("axis", &axis, {"X", "Y", "Z", "A", "B", "C"});
    o.axis = axis[0];
    g.Read("min_z_mm", &o.min_z_mm);
    g.Read("max_z_mm", &o.max_z_mm);
    g.Read("machine_zero_mm", &o.machine_zero_mm);
    g.Read("direction", &o.direction);
    g.Read("home_on_open", &o.home_on_open);
    g.Read("feed_mm_per_min", &o.feed_mm_per_min);
    g.Read("timeout_s", &o.timeout_s);
    g.Read("homing_timeout_s", &o.homing_timeout_s);
    g.Read("banner_wait_s", &o.banner_wait_s);
    g.Read("status_poll_s", &o.status_poll_s);
    g.Read("position_tolerance_mm", &o.position_tolerance_mm);
    if (g.ok()) g.FailFromValidate(o.Validate());
  }
  if (m.Has("aravis_profiler")) {
    ConfigReader& a = m.Section("aravis_profiler");
    hw::aravis::ProfilerOptions& o = c.aravis_profiler.profiler;
    a.Read("device", &o.device);
    a.ReadEnum("pixel_format", &o.pixel_format, {"Coord3D_C16", "Coord3D_C32f"});
    a.ReadEnum("trigger", &o.trigger, {"software", "Line0", "Line1", "Line2", "Line3"});
    a.Read("packet_size", &o.packet_size);
    a.Read("buffers", &o.buffers);
    a.Read("frame_timeout_ms", &o.frame_timeout_ms);
    a.Read("socket_buffer_bytes", &o.socket_buffer_bytes);
    a.Read("reconnect", &o.reconnect);
    a.Read("simulate_on", &c.aravis_profiler.simulate_on);
    a.Read("lost_packet_ratio", &c.aravis_profiler.lost_packet_ratio);
    if (a.ok()) a.FailFromValidate(o.Validate());
    if (a.ok() && !(c.aravis_profiler.lost_packet_ratio >= 0 &&
                    c.aravis_profiler.lost_packet_ratio <= 1)) {
      a.Fail("lost_packet_ratio", "must be in [0, 1]");
    }
  }
  if (m.Has("aravis")) {
    ConfigReader& a = m.Section("aravis");
    hw::aravis::CameraOptions& o = c.aravis.camera;
    a.Read("device", &o.device);
    a.Read("bit_depth", &o.bit_depth);
    a.Read("packet_size", &o.packet_size);
    a.Read("buffers", &o.buffers);
    a.Read("frame_timeout_ms", &o.frame_timeout_ms);
    a.Read("socket_buffer_bytes", &o.socket_buffer_bytes);
    a.Read("reconnect", &o.reconnect);
    a.ReadEnum("trigger", &o.trigger, {"software", "Line0", "Line1", "Line2", "Line3"});
    double roi[2] = {static_cast<double>(o.roi_width), static_cast<double>(o.roi_height)};
    a.ReadArray("roi_size_px", roi, 2);
    o.roi_width = static_cast<int>(roi[0]);
    o.roi_height = static_cast<int>(roi[1]);
    a.Read("simulate_on", &c.aravis.simulate_on);
    a.Read("lost_packet_ratio", &c.aravis.lost_packet_ratio);
    if (a.ok()) a.FailFromValidate(o.Validate());
    if (a.ok() && !(c.aravis.lost_packet_ratio >= 0 && c.aravis.lost_packet_ratio <= 1)) {
      a.Fail("lost_packet_ratio", "must be in [0, 1]");
    }
  }
  if (m.Has("lmc")) {
    ConfigReader& l = m.Section("lmc");
    hw::LmcDeviceConfig& d = c.lmc;
    l.ReadEnum("transport", &d.transport, {"usb", "sim_board"});
    ReadWord(l, "vid", &d.usb.vid);
    ReadWord(l, "pid", &d.usb.pid);
    l.Read("bus", &d.usb.bus);
    l.Read("address", &d.usb.address);
    l.Read("timeout_ms", &d.usb.timeout_ms);
    l.Read("retries", &d.usb.retries);
    hw::lmc::BoardOptions& b = d.board;
    std::string source = hw::lmc::SourceName(b.source);
    l.ReadEnum("source", &source, {"fiber", "mopa", "co2", "uv"});
    b.source = source == "mopa"  ? hw::lmc::Source::kMopa
               : source == "co2" ? hw::lmc::Source::kCo2
               : source == "uv"  ? hw::lmc::Source::kUv
                                 : hw::lmc::Source::kFiber;
    l.Read("pulse_width_ns", &b.pulse_width_ns);
    l.Read("power_invert", &b.power_invert);
    if (l.Has("startup")) {
      ConfigReader& s = l.Section("startup");
      hw::lmc::StartupOptions& st = b.startup;
      ReadWord(s, "control_mode", &st.control_mode);
      ReadWord(s, "laser_mode", &st.laser_mode);
      ReadWord(s, "delay_mode", &st.delay_mode);
      ReadWord(s, "timing_mode", &st.timing_mode);
      ReadWords(s, "standby", {&st.standby_1, &st.standby_2});
      ReadWord(s, "first_pulse_killer", &st.first_pulse_killer);
      ReadWord(s, "pwm_half_period", &st.pwm_half_period);
      ReadWord(s, "pwm_pulse_width", &st.pwm_pulse_width);
      ReadWords(s, "fpk2", {&st.fpk2[0], &st.fpk2[1], &st.fpk2[2], &st.fpk2[3]});
      ReadWords(s, "fly_res", {&st.fly_res[0], &st.fly_res[1], &st.fly_res[2], &st.fly_res[3]});
      ReadWord(s, "analog_port_1", &st.analog_port_1);
    }
    l.Read("lens_mm", &b.lens_mm);
    l.Read("swap_xy", &b.swap_xy);
    l.Read("flip_x", &b.flip_x);
    l.Read("flip_y", &b.flip_y);
    std::string focus = b.focus == hw::lmc::Focus::kNone ? "none" : "da_z_word";
    l.ReadEnum("focus", &focus, {"none", "da_z_word"});
    b.focus = focus == "none" ? hw::lmc::Focus::kNone : hw::lmc::Focus::kDaZWord;
    l.Read("z_units_per_mm", &b.z_units_per_mm);
    l.Read("focus_range_mm", &b.focus_range_mm);
    ReadWord(l, "list_ports", &b.list_ports);
    ReadWord(l, "pointer_port", &b.pointer_port);
    ReadWord(l, "trigger_port", &b.trigger_port);
    l.Read("trigger_pulse_us", &b.trigger_pulse_us);
    l.Read("open_mo_delay_us", &b.open_mo_delay_us);
    l.Read("polygon_delay_us", &b.polygon_delay_us);
    l.Read("poll_ms", &b.poll_ms);
    l.Read("list_timeout_s", &b.list_timeout_s);
    std::string correction;
    l.Read("correction", &correction);
    if (!correction.empty()) d.correction_file = ResolvePath(folder, correction);
    std::string capture;
    l.Read("capture", &capture);
    if (!capture.empty()) d.capture_file = ResolvePath(folder, capture);
    if (l.ok()) l.FailFromValidate(d.usb.Validate());
    if (l.ok()) l.FailFromValidate(b.Validate());
  }
}

void ReadJobHeader(ConfigReader& r, const LoadedJob& job, MachineSpec* machine) {
  std::string text;
  r.Read("job", &text);
  r.Read("description", &text);
  r.Skip("world");
  r.Skip("world_changes");
  ReadMachine(r, job.folder, machine);
}

Status MachineConfigFor(const LoadedJob& job, const MachineSpec& spec, hw::MachineConfig* out) {
  *out = spec.config;
  if (out->backend == "sim" && (job.world.IsDefined() || hw::NeedsSimulator(*out))) {
    if (!job.world.IsDefined()) {
      return InvalidArgument(job.path + ": the cell has simulated devices but the job names no "
                             "world");
    }
    ConfigReader w(job.world);
    sim::ReadWorld(w, &out->world);
    INSITU_RETURN_IF_ERROR(w.Finish());
  }
  return Status::Ok();
}

}  // namespace insitu::job
