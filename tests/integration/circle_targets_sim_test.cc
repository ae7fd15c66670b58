// Seed 003's spiral-filled circle targets marked by the simulated laser on the bare anodised
// plate and measured by the simulated side camera, against the simulator's truth.
//
// The test marks a 3 x 3 grid of 2.5 mm targets 40 mm apart (what a field calibration does
// with its n x n grid), grabs one side-camera frame in room light and finds the targets. Two
// estimators of each target's centre on the plate are compared with the truth (the centre of
// the circle the laser's pulses really drew, from the simulator):
//  * seed 003's: the centre of the minimum enclosing circle of the blob's outer contour,
//    taken as the image of the centre and mapped onto the plate;
//  * the perspective-correct one: the sub-pixel edge points mapped onto the plate and fitted
//    with a circle there.
// Pixels are mapped onto the plate z = 0 with the TRUE camera (pixel ray met with the plane):
// allowed in a test only, so that what is measured is the estimators, not a calibration.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "insitu/pattern/spiral_target.h"
#include "insitu/sim/world.h"
#include "insitu/vision/circle_targets.h"

namespace insitu {
namespace {

// The pixel's ray met with the plane z = z_mm, in world (= galvo) coordinates.
Eigen::Vector2d OnPlate(const sim::CameraModel& camera, const Eigen::Vector2d& pixel, double z_mm) {
  const Eigen::Vector3d dir = camera.PixelRayInWorld(pixel);
  const Eigen::Vector3d& c = camera.center_in_world();
  const double t = (z_mm - c.z()) / dir.z();
  return (c + t * dir).head<2>();
}

struct Errors {
  double sum_sq = 0.0;
  double worst = 0.0;
  int n = 0;
  void Add(double e) {
    sum_sq += e * e;
    worst = std::max(worst, e);
    ++n;
  }
  double rms() const { return n > 0 ? std::sqrt(sum_sq / n) : 0.0; }
};

TEST(CircleTargetsSim, EdgeCircleOnThePlateBeatsTheMinimumEnclosingCircle) {
  sim::WorldOptions world;  // defaults: the seed-like cell, 5 MP side camera, 8 bits
  world.part.kind = "none";  // the bare stage plate (black anodised) under the head
  world.stage.z_mm = 0.0;
  ASSERT_TRUE(world.Validate().ok());
  sim::SimWorld w(world);

  pattern::SpiralTargetOptions spiral;  // 2.5 mm, 35 um pitch
  auto path = pattern::SpiralTargetPath(spiral);
  ASSERT_TRUE(path.ok()) << path.status().ToString();
  std::vector<Eigen::Vector2d> centres;
  for (int j = -1; j <= 1; ++j) {
    for (int i = -1; i <= 1; ++i) centres.emplace_back(40.0 * i, 40.0 * j);
  }
  std::vector<sim::ListMove> moves;
  for (const Eigen::Vector2d& c : centres) {
    const auto at = [&](const Eigen::Vector2d& p) { return Eigen::Vector3d(c.x() + p.x(), c.y() + p.y(), 0.0); };
    moves.push_back({sim::ListMove::Kind::kJump, at(path->front())});
    for (size_t k = 1; k < path->size(); ++k) moves.push_back({sim::ListMove::Kind::kMark, at((*path)[k])});
  }
  sim::MarkingParams marking;
  marking.mark_speed_mm_per_s = 1000.0;
  marking.pulse_frequency_khz = 30.0;  // 33 um between pulses, about the pitch
  marking.power_fraction = 0.5;
  ASSERT_TRUE(w.ExecuteMarkingList(moves, marking).ok());
  const std::vector<sim::MarkPulse>& pulses = w.mark_pulses();
  ASSERT_FALSE(pulses.empty());
  std::printf("pulses %zu, crater %.1f um\n", pulses.size(), 1e3 * pulses[pulses.size() / 2].diameter_mm);

  ASSERT_TRUE(w.SetExposure(300000).ok());
  auto frame = w.Grab();
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  const vision::ImageView view{frame->bytes.data(), frame->width, frame->height,
                               frame->stride_bytes(), frame->bit_depth};
  vision::CircleTargetOptions options;
  options.min_diameter_px = 15;
  options.max_diameter_px = 50;
  std::vector<vision::RejectedBlob> rejected;
  auto found = vision::FindCircleTargets(view, options, &rejected);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  for (const auto& r : rejected) std::printf("rejected at %.1f %.1f: %s\n", r.center_px.x(), r.center_px.y(), r.reason.c_str());
  for (const auto& t : *found) std::printf("target %.2f %.2f r %.2f bg %.1f plateau %.1f edge %zu/%d\n", t.mec_center_px.x(), t.mec_center_px.y(), t.mec_radius_px, t.background, t.plateau, t.edge_px.size(), t.edge_rays);
  ASSERT_EQ(found->size(), centres.size());

  const sim::CameraModel& camera = w.true_camera();
  const double r_out = pattern::SpiralOuterPathRadius(spiral);
  const double circle_s = 2.0 * M_PI * r_out / marking.mark_speed_mm_per_s;
  Errors mec, edge, ellipse, centroid;
  for (const Eigen::Vector2d& nominal : centres) {
    // Truth: the circle the closing turn's pulses drew (the last circle_s of the target).
    double t_last = 0.0, z = 0.0;
    int count = 0;
    for (const sim::MarkPulse& p : pulses) {
      if ((p.point_in_world.head<2>() - nominal).norm() < 3.0) {
        t_last = std::max(t_last, p.t_s);
        z += p.point_in_world.z();
        ++count;
      }
    }
    z /= count;
    std::vector<Eigen::Vector2d> rim;
    for (const sim::MarkPulse& p : pulses) {
      if ((p.point_in_world.head<2>() - nominal).norm() < 3.0 && p.t_s > t_last - circle_s) {
        rim.push_back(p.point_in_world.head<2>());
      }
    }
    auto truth = vision::FitCircle(rim);
    ASSERT_TRUE(truth.ok());
    Eigen::Vector2d truth_px;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(truth->center.x(), truth->center.y(), z), &truth_px));
    const vision::CircleTarget* target = nullptr;
    for (const auto& t : *found) {
      if ((t.centroid_px - truth_px).norm() < 10) target = &t;
    }
    ASSERT_NE(target, nullptr);
    std::vector<Eigen::Vector2d> edge_on_plate;
    for (const Eigen::Vector2d& p : target->edge_px) edge_on_plate.push_back(OnPlate(camera, p, z));
    auto fit = vision::FitCircle(edge_on_plate);
    ASSERT_TRUE(fit.ok());
    auto el = vision::FitEllipse(target->edge_px);
    ASSERT_TRUE(el.ok());
    const double e_mec = 1e3 * (OnPlate(camera, target->mec_center_px, z) - truth->center).norm();
    const double e_edge = 1e3 * (fit->center - truth->center).norm();
    const double e_el = 1e3 * (OnPlate(camera, el->center, z) - truth->center).norm();
    const double e_cen = 1e3 * (OnPlate(camera, target->centroid_px, z) - truth->center).norm();
    mec.Add(e_mec);
    edge.Add(e_edge);
    ellipse.Add(e_el);
    centroid.Add(e_cen);
    std::printf("target (%+.0f, %+.0f): truth %.4f %.4f (rim r %.4f from %zu pulses, commanded off by %.1f um) "
                "px %.2f %.2f; errors um: mec %.1f edge-circle %.1f (rms res %.1f um, %zu pts) ellipse %.1f centroid %.1f radius %.4f\n",
                nominal.x(), nominal.y(), truth->center.x(), truth->center.y(), truth->radius, rim.size(),
                1e3 * (truth->center - nominal).norm(), truth_px.x(), truth_px.y(), e_mec, e_edge,
                1e3 * fit->rms_residual, edge_on_plate.size(), e_el, e_cen, fit->radius);
  }
  std::printf("rms/max um: mec %.1f/%.1f edge-circle %.1f/%.1f ellipse %.1f/%.1f centroid %.1f/%.1f\n",
              mec.rms(), mec.worst, edge.rms(), edge.worst, ellipse.rms(), ellipse.worst,
              centroid.rms(), centroid.worst);
}

}  // namespace
}  // namespace insitu
