#include "job/mark_verify.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <utility>

#include "insitu/core/log.h"
#include "insitu/vision/canvas.h"
#include "insitu/vision/difference.h"
#include "insitu/vision/image.h"
#include "insitu/vision/image_io.h"
#include "insitu/vision/mark_inspection.h"
#include "job/format.h"

namespace insitu::job {
namespace {

// Aims the head (every beam off) at a point: a list of one jump.
Status Aim(hw::Scanner& scanner, const Eigen::Vector3d& point_in_galvo) {
  hw::GalvoList list;
  list.entries.push_back({hw::GalvoListEntry::Kind::kJump, point_in_galvo});
  list.jump_delay_us = 2000.0;  // the mirrors settle before the picture
  return scanner.ExecuteList(list);
}

// Length-weighted centroid and rms radius of segments.
void Moments(const std::vector<pattern::Segment2>& segs, Eigen::Vector2d* centroid, double* rms) {
  double total = 0.0;
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const auto& s : segs) {
    const double l = (s.b - s.a).norm();
    c += l * 0.5 * (s.a + s.b);
    total += l;
  }
  c /= std::max(total, 1e-12);
  double r2 = 0.0;
  for (const auto& s : segs) {
    // Mean of |p - c|^2 along the segment: exact for a straight piece.
    const Eigen::Vector2d a = s.a - c, d = s.b - s.a;
    const double l = d.norm();
    r2 += l * (a.squaredNorm() + a.dot(d) + d.squaredNorm() / 3.0);
  }
  *centroid = c;
  *rms = std::sqrt(r2 / std::max(total, 1e-12));
}

// Where a side-camera pixel's ray meets the measured surface (galvo frame),
// starting from height z0; nullopt if the surface is not there.
class SideRays {
 public:
  SideRays(const calib::CalibrationSet& cal, const geometry::SurfaceModel& surface, int binning)
      : intrinsics_(cal.camera.Binned(binning)),
        galvo_from_camera_(cal.galvo.camera_from_galvo.inverse()),
        surface_(surface) {}

  // Also the surface area each pixel covers, relative (*area: distance^2 / cos
  // incidence), so a centroid over pixels is one over the surface: a slope
  // facing the camera packs more pixels into each square millimetre than one
  // turned away.
  std::vector<std::optional<Eigen::Vector2d>> Trace(const std::vector<Eigen::Vector2d>& px,
                                                    double z0, std::vector<double>* area) const {
    area->assign(px.size(), 0.0);
    const std::vector<Eigen::Vector2d> norm = intrinsics_.Undistort(px);
    std::vector<std::optional<Eigen::Vector2d>> out(px.size());
    const Eigen::Vector3d o = galvo_from_camera_.translation();
    for (size_t i = 0; i < px.size(); ++i) {
      const Eigen::Vector3d d =
          galvo_from_camera_.linear() * Eigen::Vector3d(norm[i].x(), norm[i].y(), 1.0);
      if (std::abs(d.z()) < 1e-9) continue;
      double z = z0;
      Eigen::Vector3d p, normal = Eigen::Vector3d::UnitZ();
      bool found = true;
      for (int it = 0; it < 6; ++it) {
        p = o + d * ((z - o.z()) / d.z());
        const auto s = surface_.At(p.x(), p.y());
        if (!s) {
          found = false;
          break;
        }
        normal = s->normal;
        if (std::abs(s->z_mm - z) < 1e-4) break;
        z = s->z_mm;
      }
      if (!found) continue;
      out[i] = p.head<2>();
      const Eigen::Vector3d ray = p - o;
      (*area)[i] = ray.squaredNorm() / std::max(0.05, std::abs(ray.normalized().dot(normal)));
    }
    return out;
  }

  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_galvo) const {
    return intrinsics_.Project(galvo_from_camera_.inverse() * point_in_galvo);
  }

 private:
  calib::CameraIntrinsics intrinsics_;
  Eigen::Isometry3d galvo_from_camera_;
  const geometry::SurfaceModel& surface_;
};

// Spots where the design hatches every line over +-half_width across and
// +-half_length along.
std::vector<Eigen::Vector2d> FullyHatchedSpots(const ItemDesign& d, double half_width,
                                               double half_length, int wanted) {
  const double th = d.hatch_angle_deg * M_PI / 180.0, s = d.spacing_mm;
  const Eigen::Vector2d a(std::cos(th), std::sin(th)), n(-std::sin(th), std::cos(th));
  std::map<long, std::vector<std::pair<double, double>>> lines;  // line index -> runs along a
  std::optional<double> t_ref;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& seg : d.placed) {
    const Eigen::Vector2d v = seg.b - seg.a;
    if (v.norm() < 1e-9 || std::abs(v.normalized().dot(n)) > 0.02) continue;  // not a hatch line
    const double t = 0.5 * (seg.a + seg.b).dot(n);
    if (!t_ref) t_ref = t;
    const double ra = seg.a.dot(a), rb = seg.b.dot(a);
    lines[std::lround((t - *t_ref) / s)].push_back({std::min(ra, rb), std::max(ra, rb)});
    lo = lo.cwiseMin(seg.a.cwiseMin(seg.b));
    hi = hi.cwiseMax(seg.a.cwiseMax(seg.b));
  }
  std::vector<Eigen::Vector2d> candidates;
  if (!t_ref) return candidates;
  // A line cut into pieces (wrapped onto a curve, or split at steps) is one
  // run.
  for (auto& [key, runs] : lines) {
    std::sort(runs.begin(), runs.end());
    std::vector<std::pair<double, double>> merged;
    for (const auto& r : runs) {
      if (!merged.empty() && r.first <= merged.back().second + 1e-6) {
        merged.back().second = std::max(merged.back().second, r.second);
      } else {
        merged.push_back(r);
      }
    }
    runs = std::move(merged);
  }
  const int k_max = static_cast<int>(std::ceil(half_width / s));
  const double step = std::max(0.05, 0.5 * half_width);
  for (double y = lo.y(); y <= hi.y(); y += step) {
    for (double x = lo.x(); x <= hi.x(); x += step) {
      const Eigen::Vector2d c(x, y);
      const long k0 = std::lround((c.dot(n) - *t_ref) / s);
      const double along = c.dot(a);
      bool full = true;
      for (int k = -k_max; k <= k_max && full; ++k) {
        const auto it = lines.find(k0 + k);
        full = it != lines.end() &&
               std::any_of(it->second.begin(), it->second.end(), [&](const auto& r) {
                 return r.first <= along - half_length && r.second >= along + half_length;
               });
      }
      // The spot sits on a line's position across (so the measured window is
      // symmetric).
      if (full) candidates.push_back(c + n * (*t_ref + k0 * s - c.dot(n)));
    }
  }
  // Spread: the first nearest the pattern's middle, then each farthest from
  // those taken.
  std::vector<Eigen::Vector2d> spots;
  if (candidates.empty()) return spots;
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  spots.push_back(*std::min_element(candidates.begin(), candidates.end(), [&](auto& p, auto& q) {
    return (p - mid).squaredNorm() < (q - mid).squaredNorm();
  }));
  while (static_cast<int>(spots.size()) < wanted) {
    double best = 0.0;
    Eigen::Vector2d pick;
    for (const auto& c : candidates) {
      double dmin = 1e300;
      for (const auto& p : spots) dmin = std::min(dmin, (c - p).norm());
      if (dmin > best) best = dmin, pick = c;
    }
    if (best < 2.0 * half_width) break;  // nothing new left
    spots.push_back(pick);
  }
  return spots;
}

// The design's shape per item (galvo xy, mm) and the mean focus height of the list's marks.
struct DesignShape {
  std::vector<Eigen::Vector2d> centroid;
  std::vector<double> rms;
  std::vector<Eigen::Vector2d> box_lo, box_hi;
  double z_mean = 0.0;
};

DesignShape ShapeOf(const MarkDesign& design) {
  const size_t n_items = design.items.size();
  DesignShape d;
  d.centroid.resize(n_items);
  d.rms.resize(n_items);
  d.box_lo.assign(n_items, Eigen::Vector2d::Constant(1e300));
  d.box_hi.assign(n_items, Eigen::Vector2d::Constant(-1e300));
  for (size_t k = 0; k < n_items; ++k) {
    Moments(design.items[k].placed, &d.centroid[k], &d.rms[k]);
    for (const auto& s : design.items[k].placed) {
      d.box_lo[k] = d.box_lo[k].cwiseMin(s.a.cwiseMin(s.b));
      d.box_hi[k] = d.box_hi[k].cwiseMax(s.a.cwiseMax(s.b));
    }
  }
  for (const auto& p : design.mark_points) d.z_mean += p.z();
  d.z_mean /= std::max<size_t>(1, design.mark_points.size());
  return d;
}

// A rectangle of the side camera's frame, pixels.
struct Window {
  int x0 = 0, y0 = 0, width = 0, height = 0;
};

// The pattern's window in the frame (its projection and a margin), clipped to the frame.
Window PatternWindow(const SideRays& rays, const MarkDesign& design, double z_mean,
                     const Frame& after) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& item : design.items) {
    for (const auto& s : item.placed) {
      for (const Eigen::Vector2d& p : {s.a, s.b}) {
        const Eigen::Vector2d px = rays.Project({p.x(), p.y(), z_mean});
        lo = lo.cwiseMin(px);
        hi = hi.cwiseMax(px);
      }
    }
  }
  const int margin = 25;
  Window w;
  w.x0 = std::max(0, static_cast<int>(lo.x()) - margin);
  w.y0 = std::max(0, static_cast<int>(lo.y()) - margin);
  w.width = std::max(0, std::min(after.width, static_cast<int>(hi.x()) + margin) - w.x0);
  w.height = std::max(0, std::min(after.height, static_cast<int>(hi.y()) + margin) - w.y0);
  return w;
}

// The marks the side camera saw, per item: darkening-weighted (and surface-area weighted)
// centroid and second moment on the measured surface, galvo xy.
struct SeenMarks {
  std::vector<double> total, r2;
  std::vector<Eigen::Vector2d> centroid;
  size_t pixels = 0;  // pixels that darkened
};

Result<SeenMarks> FindMarks(const SideRays& rays, const DesignShape& shape, const Frame& before,
                            const Frame& after, const Window& win) {
  const size_t n_items = shape.centroid.size();
  const vision::ImageView after_roi =
      vision::ViewOf(after).Crop(win.x0, win.y0, win.width, win.height);
  // A mark is where the window darkened beyond its noise (most of it is unmarked).
  auto dark = vision::FindDarkened(
      vision::ViewOf(before).Crop(win.x0, win.y0, win.width, win.height), after_roi);
  if (!dark.ok()) return dark.status().Prefixed("verify: side camera");
  std::vector<Eigen::Vector2d> px;
  for (const Eigen::Vector2d& p : dark->px) px.push_back(p + Eigen::Vector2d(win.x0, win.y0));
  std::vector<double> w = std::move(dark->depth);
  std::vector<double> area;
  const auto xy = rays.Trace(px, shape.z_mean, &area);
  // Each marked pixel belongs to the item whose footprint (+0.5 mm) holds it.
  SeenMarks seen;
  seen.total.assign(n_items, 0.0);
  seen.r2.assign(n_items, 0.0);
  seen.centroid.assign(n_items, Eigen::Vector2d::Zero());
  seen.pixels = px.size();
  std::vector<double>& total = seen.total;
  std::vector<Eigen::Vector2d>& c = seen.centroid;
  std::vector<int> owner(px.size(), -1);
  const Eigen::Vector2d grow(0.5, 0.5);
  for (size_t i = 0; i < xy.size(); ++i) {
    w[i] *= area[i];
    if (!xy[i] || !(w[i] > 0)) continue;
    for (size_t k = 0; k < n_items; ++k) {
      if ((xy[i]->array() >= (shape.box_lo[k] - grow).array()).all() &&
          (xy[i]->array() <= (shape.box_hi[k] + grow).array()).all()) {
        owner[i] = static_cast<int>(k);
        c[k] += w[i] * *xy[i];
        total[k] += w[i];
        break;
      }
    }
  }
  for (size_t k = 0; k < n_items; ++k) {
    if (total[k] > 0) c[k] /= total[k];
  }
  for (size_t i = 0; i < xy.size(); ++i) {
    if (owner[i] >= 0) seen.r2[owner[i]] += w[i] * (*xy[i] - c[owner[i]]).squaredNorm();
  }
  return seen;
}

// Placement and size errors against the design: the worst item's, and every item's when
// there are several.
void ReportPlacement(const DesignShape& shape, const SeenMarks& seen, Report* report) {
  auto log = Logger("job");
  const size_t n_items = shape.centroid.size();
  const std::vector<Eigen::Vector2d>& design_c = shape.centroid;
  const std::vector<Eigen::Vector2d>& c = seen.centroid;
  double worst = -1.0, worst_size = 0.0;
  for (size_t k = 0; k < n_items; ++k) {
    if (seen.total[k] <= 0) {
      report->warnings.push_back("placement of item " + std::to_string(k) +
                                 " not verified: no marks seen by the side camera");
      continue;
    }
    const double err = (c[k] - design_c[k]).norm();
    const double size_pct = 100.0 * (std::sqrt(seen.r2[k] / seen.total[k]) / shape.rms[k] - 1.0);
    if (err > worst) {
      worst = err;
      report->metrics["placement_error_x_mm"] = c[k].x() - design_c[k].x();
      report->metrics["placement_error_y_mm"] = c[k].y() - design_c[k].y();
    }
    if (std::abs(size_pct) >= std::abs(worst_size)) worst_size = size_pct;
    if (n_items > 1) {
      report->metrics["item" + std::to_string(k) + "_placement_error_mm"] = err;
      report->metrics["item" + std::to_string(k) + "_size_error_pct"] = size_pct;
    }
    log->info(
        "verify: item {} centred at ({:.3f}, {:.3f}) mm, design "
        "({:.3f}, {:.3f}): {:.3f} mm off",
        k, c[k].x(), c[k].y(), design_c[k].x(), design_c[k].y(), err);
  }
  if (worst >= 0) {
    report->metrics["placement_error_mm"] = worst;
    report->metrics["pattern_size_error_pct"] = worst_size;
    report->metrics["side_marked_pixels"] = static_cast<double>(seen.pixels);
  }
}

// mark.png: the side camera's view of the marks, 4x, with the design over
// it. A picture that cannot be written is a warning.
void SaveMarkPicture(const SideRays& rays, const MarkDesign& design, const DesignShape& shape,
                     const SeenMarks& seen, const Frame& after, const Window& win,
                     const std::filesystem::path& dir, Report* report) {
  const vision::ImageView after_roi =
      vision::ViewOf(after).Crop(win.x0, win.y0, win.width, win.height);
  Status saved = Status::Ok();
  if (auto view = vision::Canvas::FromGray(after_roi, 4.0); view.ok()) {
    vision::Canvas overlay = view->Clone();
    const auto to_view = [&](const Eigen::Vector2d& p) {
      const Eigen::Vector2d q = rays.Project({p.x(), p.y(), shape.z_mean});
      return Eigen::Vector2d(static_cast<int>(std::lround(4.0 * (q.x() - win.x0) + 1.5)),
                             static_cast<int>(std::lround(4.0 * (q.y() - win.y0) + 1.5)));
    };
    constexpr int kGreen = 0x00C800, kRed = 0xFF0000;
    for (const auto& item : design.items) {
      for (const auto& s : item.placed) {
        overlay.Line(to_view(s.a), to_view(s.b), {.rgb = kGreen, .smooth = true});
      }
    }
    view->Blend(overlay, 0.35);
    for (size_t k = 0; k < shape.centroid.size(); ++k) {
      view->Cross(to_view(shape.centroid[k]), 24, {.rgb = kGreen, .thickness = 2});
      if (seen.total[k] > 0) {
        view->Cross(to_view(seen.centroid[k]), 24, {.rgb = kRed, .thickness = 2});
      }
    }
    view->Text("design (green) over the side camera after marking; red: measured centre",
               Eigen::Vector2d(8, 20), 0.5, {.rgb = 0xFFFF00});
    saved = view->WritePng((dir / "mark.png").string());
  } else {
    saved = view.status();
  }
  if (saved.ok()) {
    report->artifacts["mark"] = "mark.png";
  } else {
    report->warnings.push_back("mark.png: " + saved.message());
  }
}

// 1. Placement and size from what darkened in the side camera.
Status VerifyPlacement(const calib::CalibrationSet& cal, const geometry::SurfaceModel& surface,
                       const MarkDesign& design, const DesignShape& shape, const Frame& before,
                       const Frame& after, const std::filesystem::path& dir, Report* report) {
  const SideRays rays(cal, surface, after.binning);
  const Window win = PatternWindow(rays, design, shape.z_mean, after);
  if (before.width != after.width || before.height != after.height || win.width * win.height < 16) {
    report->warnings.push_back(
        "placement not verified: the pattern is not in the side camera's view");
    return Status::Ok();
  }
  INSITU_ASSIGN_OR_RETURN(const SeenMarks seen, FindMarks(rays, shape, before, after, win));
  ReportPlacement(shape, seen, report);
  SaveMarkPicture(rays, design, shape, seen, after, win, dir, report);
  return Status::Ok();
}

// 2. Line spacing (and width where the lines stand apart) at fully hatched
// spots, per spacing asked.
Status VerifyLineSpacing(hw::Scanner& scanner, hw::Camera& coax,
                         const geometry::SurfaceModel& surface, const MarkDesign& design,
                         const VerifyOptions& o, const std::filesystem::path& dir, Report* report) {
  auto log = Logger("job");
  const auto height_at = [&](const Eigen::Vector2d& p) -> std::optional<double> {
    const auto s = surface.At(p.x(), p.y());
    if (!s) return std::nullopt;
    return s->z_mm;
  };
  struct Pool {
    double sum = 0.0, var = 0.0, width = 0.0, width_sd = 0.0;
    int gaps = 0, spots = 0, widths = 0;
  };
  std::map<long, Pool> pools;  // by the spacing asked, um
  long first_asked = -1;
  bool saved = false;
  for (const ItemDesign& item : design.items) {
    if (!(item.spacing_mm > 0)) continue;
    const long asked = std::lround(item.spacing_mm * 1e3);
    if (first_asked < 0) first_asked = asked;
    Pool& pool = pools[asked];
    std::vector<Eigen::Vector2d> spots;
    double half_width = 0.0, half_length = 0.0;
    for (int lines : {10, 6, 3}) {
      half_width = lines * item.spacing_mm;
      half_length = std::max(0.1, std::min(0.3, half_width));
      spots = FullyHatchedSpots(item, half_width, half_length, o.spacing_spots);
      if (!spots.empty()) break;
    }
    for (const Eigen::Vector2d& spot : spots) {
      const auto z = height_at(spot);
      if (!z) continue;
      INSITU_RETURN_IF_ERROR(Aim(scanner, {spot.x(), spot.y(), *z}));
      INSITU_ASSIGN_OR_RETURN(Frame f, coax.Grab());
      vision::HatchMeasureOptions m;
      m.pixel_um = o.coaxial_pixel_um;
      m.camera_rotation_deg = o.coaxial_rotation_deg;
      m.hatch_angle_deg = item.hatch_angle_deg;
      m.spacing_um = item.spacing_mm * 1e3;
      m.centre_px = {0.5 * (f.width - 1), 0.5 * (f.height - 1)};
      // Lines centred on the spot; keep a quarter spacing off the last ones on
      // each side.
      m.half_width_um = (half_width - 0.25 * item.spacing_mm) * 1e3;
      m.half_length_um = half_length * 1e3;
      const auto r = vision::MeasureHatch(vision::ViewOf(f), m);
      if (!saved) {
        const Status written = vision::WritePng((dir / "coaxial.png").string(), vision::ViewOf(f));
        if (written.ok()) {
          report->artifacts["coaxial"] = "coaxial.png";
        } else {
          report->warnings.push_back("coaxial.png: " + written.message());
        }
        saved = true;
      }
      if (!r.ok()) {
        report->warnings.push_back(Fmt("line spacing at (%.2f, %.2f) mm: ", spot.x(), spot.y()) +
                                   r.status().message());
        continue;
      }
      const int g = r->lines - 1;
      pool.sum += r->spacing_um * g;
      pool.var += r->spacing_std_um * r->spacing_std_um * g;
      pool.gaps += g;
      ++pool.spots;
      if (r->separated) pool.width += r->width_um, pool.width_sd += r->width_std_um, ++pool.widths;
      log->info(
          "verify: spacing {:.2f} +- {:.2f} um (asked {}) over {} lines "
          "at ({:.2f}, {:.2f}) mm",
          r->spacing_um, r->spacing_std_um, asked, r->lines, spot.x(), spot.y());
    }
  }
  for (const auto& [asked, pool] : pools) {
    if (pool.spots == 0) {
      report->warnings.push_back("line spacing " + std::to_string(asked) +
                                 " um not verified: no fully hatched spot could be measured");
      continue;
    }
    const std::string tag = std::to_string(asked);
    const double mean = pool.sum / pool.gaps, sd = std::sqrt(pool.var / pool.gaps);
    report->metrics["line_spacing_" + tag + "_um"] = mean;
    report->metrics["line_spacing_std_" + tag + "_um"] = sd;
    report->metrics["line_spacing_spots_" + tag] = pool.spots;
    if (pool.widths > 0) report->metrics["line_width_" + tag + "_um"] = pool.width / pool.widths;
    if (asked == first_asked) {
      report->metrics["line_spacing_um"] = mean;
      report->metrics["line_spacing_std_um"] = sd;
      report->metrics["line_spacing_asked_um"] = static_cast<double>(asked);
      if (pool.widths > 0) {
        report->metrics["line_width_um"] = pool.width / pool.widths;
        report->metrics["line_width_std_um"] = pool.width_sd / pool.widths;
      }
    }
  }
  return Status::Ok();
}

// 3. Focus: sweep the dynamic focus at marked points; sharpest = the surface.
Status VerifyFocus(hw::Scanner& scanner, hw::Camera& coax, const MarkDesign& design,
                   const VerifyOptions& o, Report* report) {
  auto log = Logger("job");
  const int np = std::min<int>(o.focus_points, static_cast<int>(design.mark_points.size()));
  double worst = -1.0, sum2 = 0.0;
  int measured = 0;
  for (int i = 0; i < np; ++i) {
    const Eigen::Vector3d& p =
        design.mark_points[static_cast<size_t>((i + 0.5) * design.mark_points.size() / np)];
    std::vector<double> zs, sharp;
    bool ok = true;
    for (double dz = -o.focus_sweep_mm; dz <= o.focus_sweep_mm + 1e-9; dz += o.focus_step_mm) {
      if (!Aim(scanner, {p.x(), p.y(), p.z() + dz}).ok()) {
        ok = false;
        break;
      }
      auto f = coax.Grab();
      if (!f.ok()) return f.status();
      zs.push_back(p.z() + dz);
      // The image centre, 0.5 mm square: the marks right at the point.
      const int half = static_cast<int>(250.0 / o.coaxial_pixel_um);
      sharp.push_back(vision::Sharpness(vision::ViewOf(*f),
                                        {0.5 * (f->width - 1), 0.5 * (f->height - 1)}, half));
    }
    const auto best = ok ? vision::BestFocus(zs, sharp)
                         : Result<double>(FailedPrecondition("sweep left the focus range"));
    if (!best.ok()) {
      report->warnings.push_back(Fmt("focus at (%.2f, %.2f) mm: ", p.x(), p.y()) +
                                 best.status().message());
      continue;
    }
    const double err = p.z() - *best;
    worst = std::max(worst, std::abs(err));
    sum2 += err * err;
    ++measured;
    log->info("verify: focus at ({:.2f}, {:.2f}): list z {:.3f}, sharpest {:.3f} mm", p.x(), p.y(),
              p.z(), *best);
  }
  if (measured > 0) {
    report->metrics["focus_error_max_mm"] = worst;
    report->metrics["focus_error_rms_mm"] = std::sqrt(sum2 / measured);
    report->metrics["focus_points"] = measured;
  } else if (np > 0) {
    report->warnings.push_back("focus not verified: no sweep found a sharpest image");
  }
  return Status::Ok();
}

}  // namespace

Status VerifyOptions::Validate() const {
  if (!(coaxial_pixel_um > 0)) return InvalidArgument("coaxial_pixel_um must be > 0");
  if (!(coaxial_exposure_ms > 0)) return InvalidArgument("coaxial_exposure_ms must be > 0");
  if (spacing_spots < 1) return InvalidArgument("spacing_spots must be >= 1");
  if (focus_points < 0) return InvalidArgument("focus_points must be >= 0");
  if (!(focus_step_mm > 0) || !(focus_sweep_mm >= 2 * focus_step_mm)) {
    return InvalidArgument("focus_sweep_mm must be >= 2 focus_step_mm > 0");
  }
  if (!(side_target_level > 10 && side_target_level < 250)) {
    return InvalidArgument("side_target_level must be in (10, 250) grey levels");
  }
  return Status::Ok();
}

Result<Frame> GrabSideView(hw::Machine& machine, const VerifyOptions& o, double* exposure_us) {
  INSITU_RETURN_IF_ERROR(machine.scanner->StopPointer());
  INSITU_RETURN_IF_ERROR(machine.camera->SetBinning(1));
  double exposure = *exposure_us > 0 ? *exposure_us : 100e3;
  for (int attempt = 0; attempt < 4; ++attempt) {
    INSITU_RETURN_IF_ERROR(machine.camera->SetExposure(exposure));
    INSITU_ASSIGN_OR_RETURN(Frame f, machine.camera->Grab());
    if (*exposure_us > 0) return f;  // the exposure of the frame before marking
    // The bare part's level: the 98th percentile of the frame's centre half.
    std::vector<int> v;
    for (int y = f.height / 4; y < 3 * f.height / 4; y += 4) {
      for (int x = f.width / 4; x < 3 * f.width / 4; x += 4) v.push_back(f.at(x, y));
    }
    std::nth_element(v.begin(), v.begin() + static_cast<long>(0.98 * (v.size() - 1)), v.end());
    const double level = v[static_cast<size_t>(0.98 * (v.size() - 1))] * 255.0 / f.max_value();
    if (std::abs(level - o.side_target_level) < 0.15 * o.side_target_level || attempt == 3) {
      *exposure_us = exposure;
      return f;
    }
    exposure = std::clamp(exposure * o.side_target_level / std::max(level, 2.0), 1e3, 2e6);
  }
  return FailedPrecondition("side camera: no usable exposure");
}

Status VerifyMarks(hw::Machine& machine, const calib::CalibrationSet& cal,
                   const geometry::SurfaceModel& surface, const MarkDesign& design,
                   const VerifyOptions& o, const Frame& before, const Frame& after,
                   const std::string& out_dir, Report* report) {
  const std::filesystem::path dir(out_dir);
  const DesignShape shape = ShapeOf(design);
  INSITU_RETURN_IF_ERROR(VerifyPlacement(cal, surface, design, shape, before, after, dir, report));
  if (!machine.coaxial) {
    report->warnings.push_back("no coaxial camera: line spacing and focus not verified");
    return Status::Ok();
  }
  hw::Camera& coax = *machine.coaxial;
  INSITU_RETURN_IF_ERROR(coax.SetExposure(o.coaxial_exposure_ms * 1e3));
  INSITU_RETURN_IF_ERROR(
      VerifyLineSpacing(*machine.scanner, coax, surface, design, o, dir, report));
  return VerifyFocus(*machine.scanner, coax, design, o, report);
}

}  // namespace insitu::job
