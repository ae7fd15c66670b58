// Contours from groove centres (seed 002, section 2.2) on generated contours: clustering splits
// them, centroids match them whatever their order, and a contour displaced, stretched and
// wavering is split into its offset (eq. 21), scale and local error (eq. 22-23).
#include "insitu/inspect/contours.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

namespace insitu::inspect {
namespace {

using Eigen::Vector2d;

// A w x h rectangle about `centre`, a point every `step` mm along it.
Points2 Rectangle(const Vector2d& centre, double w, double h, double step) {
  Points2 out;
  const Vector2d corners[5] = {
      {-w / 2, -h / 2}, {w / 2, -h / 2}, {w / 2, h / 2}, {-w / 2, h / 2}, {-w / 2, -h / 2}};
  for (int k = 0; k < 4; ++k) {
    const Vector2d a = corners[k], b = corners[k + 1];
    const int n = static_cast<int>(std::round((b - a).norm() / step));
    for (int i = 0; i < n; ++i) out.push_back(centre + a + (b - a) * (static_cast<double>(i) / n));
  }
  return out;
}

Points2 Circle(const Vector2d& centre, double r, double step) {
  Points2 out;
  const int n = static_cast<int>(std::round(2 * M_PI * r / step));
  for (int i = 0; i < n; ++i) {
    const double t = 2 * M_PI * i / n;
    out.push_back(centre + r * Vector2d(std::cos(t), std::sin(t)));
  }
  return out;
}

TEST(Contours, ClusteringSplitsContoursAndDropsStrays) {
  Points2 all = Rectangle({0, 0}, 80, 40, 0.2);
  const Points2 circle = Circle({120, 0}, 20, 0.2);
  all.insert(all.end(), circle.begin(), circle.end());
  all.push_back({60, 60});  // two stray centres (a profile across a scratch)
  all.push_back({60.1, 60});
  const auto clusters = ClusterPoints(all, 5.0);
  ASSERT_EQ(clusters.size(), 2u);
  EXPECT_EQ(clusters[0].size(), Rectangle({0, 0}, 80, 40, 0.2).size());
  EXPECT_EQ(clusters[1].size(), circle.size());
}

TEST(Contours, CentroidsMatchContoursWhateverTheirOrder) {
  const std::vector<Points2> design = {Rectangle({0, 0}, 80, 40, 0.5), Circle({120, 0}, 20, 0.5),
                                       Circle({120, 80}, 10, 0.5)};
  std::vector<Points2> measured;
  for (int k : {2, 0}) {  // the third contour not engraved; the order scrambled
    Points2 m = design[k];
    for (Vector2d& p : m) p += Vector2d(0.3, -0.2);
    measured.push_back(m);
  }
  const auto matches = MatchContours(design, measured, 5.0);
  ASSERT_EQ(matches.size(), 2u);
  EXPECT_EQ(matches[0].measured, 0);
  EXPECT_EQ(matches[0].design, 2);
  EXPECT_EQ(matches[1].measured, 1);
  EXPECT_EQ(matches[1].design, 0);
  EXPECT_NEAR(matches[0].centroid_distance_mm, std::hypot(0.3, 0.2), 1e-9);
  // Nothing within reach: unmatched.
  EXPECT_TRUE(MatchContours(design, {Circle({500, 500}, 5, 0.5)}, 5.0).empty());
}

// A corner overshot (seed 002 Fig. 7): the machine runs 0.1 mm past the corner before it turns
// back to the second leg. Plain nearest points match the design's corner to the path through it
// (0 off); eq. 22's correction takes the point that claims the corner from the far side, the
// overshoot's tip, and the corner shows its 0.1 mm.
TEST(Contours, ACornerOvershootIsSeenAtTheCorner) {
  Points2 design, measured;
  for (int i = 0; i <= 1000; ++i) design.push_back({-10.0 + 0.01 * i, 0.0});     // to the corner
  for (int i = 1; i <= 1000; ++i) design.push_back({0.0, 0.01 * i});             // and up
  for (int i = 0; i <= 1010; ++i) measured.push_back({-10.0 + 0.01 * i, 0.0});   // past it
  for (int i = 1; i <= 10; ++i) measured.push_back({0.1 - 0.01 * i, 0.01 * i});  // back
  for (int i = 11; i <= 1000; ++i) measured.push_back({0.0, 0.01 * i});
  auto e = CompareContour(design, measured);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  // The design points at the corner (within 15 um of it, after the design was resampled).
  double largest = 0, nearest_largest = 0;
  int at_corner = 0;
  for (size_t i = 0; i < e->design.size(); ++i) {
    if (e->design[i].norm() > 0.015) continue;
    ++at_corner;
    double nearest = 1e9;
    for (const Vector2d& q : measured) {
      nearest = std::min(nearest, (q + e->offset_mm - e->design[i]).norm());
    }
    nearest_largest = std::max(nearest_largest, nearest);
    largest = std::max(largest, e->local_mm[i]);
  }
  ASSERT_GE(at_corner, 1);
  // What plain nearest points would say: a sample spacing and the offset the overshoot adds to
  // the centroid, ~0.01 mm.
  EXPECT_LT(nearest_largest, 0.02);
  EXPECT_GT(largest, 0.08);  // eq. 22: the overshoot's tip
  EXPECT_LT(largest, 0.12);
}

// The panel's design rectangle, 80 x 40 mm, engraved 0.3 mm off in x and -0.2 mm in y (the
// datum), 0.2 % larger about its centre (the clamped panel's bending), with a 10 um rms
// wander across the line (the machine's dynamics), measured every 10 um along it (a 5 kHz
// profiler at 50 mm/s). Across the line the wander is 7 um rms; that is the local error left
// after offset and scale.
TEST(Contours, AnEngravedContourSplitsIntoOffsetScaleAndLocalError) {
  const Points2 design = Rectangle({100, 50}, 80, 40, 0.5);
  Points2 measured;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> wander(0.0, 0.010);
  const Vector2d centre(100, 50);
  for (const Vector2d& p : Rectangle({100, 50}, 80, 40, 0.01)) {
    const Vector2d q = centre + 1.002 * (p - centre) + Vector2d(0.3, -0.2);
    measured.push_back(q + Vector2d(wander(rng), wander(rng)) / std::sqrt(2.0));
  }
  auto e = CompareContour(design, measured);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  std::printf("offset %.4f %.4f mm, scale %.4f %%, local rms %.1f um, max %.1f um\n",
              e->offset_mm.x(), e->offset_mm.y(), e->scale_pct, 1e3 * e->local_rms_mm,
              1e3 * e->local_max_mm);
  // Eq. 21: E = design centroid - measured centroid; 24,000 points of 7 um wander each: well
  // under 1 um, plus the resampled design's own centroid (its samples fall 10 um apart, not
  // exactly where the rectangle's corners are: ~1 um).
  EXPECT_NEAR(e->offset_mm.x(), -0.3, 0.002);
  EXPECT_NEAR(e->offset_mm.y(), 0.2, 0.002);
  EXPECT_NEAR(e->scale_pct, 0.2, 0.005);
  EXPECT_GT(e->local_rms_mm, 0.005);
  EXPECT_LT(e->local_rms_mm, 0.009);
  // The largest: the wander's tail over 24,000 points, ~4 sigma of 7 um; corners included.
  EXPECT_LT(e->local_max_mm, 0.040);
  // Before the scale is taken out, the corners stand 0.2 % x 45 mm = 89 um off.
  double largest = 0;
  for (double v : e->local_mm) largest = std::max(largest, v);
  EXPECT_GT(largest, 0.07);
  ASSERT_EQ(e->error_mm.size(), e->design.size());
  EXPECT_GT(e->design.size(), 20 * design.size());  // resampled to the measured 10 um
  EXPECT_NEAR(e->error_mm[0], e->offset_mm.norm() + e->local_mm[0], 1e-12);  // eq. 23

  EXPECT_FALSE(CompareContour({}, measured).ok());
  Points2 bad = measured;
  bad[7] = Vector2d(NAN, 0.0);
  EXPECT_FALSE(CompareContour(design, bad).ok());
}

}  // namespace
}  // namespace insitu::inspect

namespace insitu::inspect {
namespace {

// A 27 x 17 mm pocket with 4 mm corners as CAD flattens it: each corner's arc 64 vertices, the
// straight sides two points each, its first point not repeated at the end.
Points2 RoundedPocket() {
  Points2 design;
  const double r = 4.0;
  const Vector2d corner[4] = {{41.0, 31.0}, {14.0, 31.0}, {14.0, 14.0}, {41.0, 14.0}};
  for (int k = 0; k < 4; ++k) {
    for (int i = 0; i <= 64; ++i) {
      const double t = (k + i / 64.0) * M_PI / 2;
      design.push_back(corner[k] + r * Vector2d(std::cos(t), std::sin(t)));
    }
  }
  return design;
}

// A station every `spacing` (rounded to divide it) along the closed outline, from half a spacing
// past its start: the point and the outline's unit tangent there.
struct Station {
  Vector2d point, tangent;
};
std::vector<Station> Stations(const Points2& outline, double spacing) {
  Points2 chain = outline;
  chain.push_back(outline.front());
  double length = 0;
  for (size_t i = 1; i < chain.size(); ++i) length += (chain[i] - chain[i - 1]).norm();
  const int n = static_cast<int>(std::round(length / spacing));
  std::vector<Station> out;
  size_t seg = 1;
  double start = 0;
  for (int k = 0; k < n; ++k) {
    const double at = (k + 0.5) * length / n;
    while (start + (chain[seg] - chain[seg - 1]).norm() < at) {
      start += (chain[seg] - chain[seg - 1]).norm();
      ++seg;
    }
    const Vector2d t = (chain[seg] - chain[seg - 1]).normalized();
    out.push_back({chain[seg - 1] + t * (at - start), t});
  }
  return out;
}

// A closed design as CAD gives it (a rounded rectangle's vertices, the straight sides two
// points each, the corners many; its first point not repeated at the end) against centres
// measured exactly on it, half a spacing along from the design's own samples: no offset, no
// scale, and no local error but the resampled design's 0.2 mm chords cutting the corners'
// flattened arcs (a vertex every 1.4 deg: 0.1 mm x 0.012 = 1.2 um; the chords' 1.3 um sagitta
// on a 4 mm radius). The seam between the last and first points counts like any other
// stretch of the contour.
TEST(Contours, AClosedDesignComparesCleanAcrossItsSeam) {
  const Points2 design = RoundedPocket();
  // The measured centres: every 0.2 mm along the closed outline, from 0.1 mm past its start.
  Points2 measured;
  for (const Station& st : Stations(design, 0.2)) measured.push_back(st.point);
  auto e = CompareContour(design, measured, /*closed=*/true);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_LT(e->offset_mm.norm(), 1e-6);
  // The resampled design's chords lie inside the corners' arcs by up to 2.5 um, over a sixth of
  // the outline: seen as a scale, ~2e-5 (0.3 um over a 15 mm half size).
  EXPECT_LT(std::abs(e->scale_pct), 5e-3);
  EXPECT_LT(e->local_max_mm, 0.003);  // 1.2 + 1.3 um
  EXPECT_EQ(e->design.size(), measured.size());
}

// What a line profiler gives: one centre per station along the design, found on the profile
// across the groove there, so each centre shows only the contour's displacement across the line
// (displaced along a side, the groove slides along the profile's line unseen). The rounded
// rectangle displaced by (0.3, -0.2) mm and 0.05 % large, one centre every 0.5 mm: the
// offset and scale come back whole (the points' own mean would show ~0.4 and ~0.6 of the two
// displacements: the shares of the outline running across each). The local error is the
// corners': there the displacement along one side is across the arc.
TEST(Contours, AContourSeenOnlyAcrossTheLineGivesItsWholeOffset) {
  const Points2 design = RoundedPocket();
  Points2 chain = design;
  chain.push_back(design.front());
  const Vector2d d(0.3, -0.2), c(27.5, 22.5);
  const double scale = 0.0005;
  Points2 measured;
  for (const Station& st : Stations(design, 0.5)) {
    const Vector2d p = st.point, normal(-st.tangent.y(), st.tangent.x());
    // Where the normal through p crosses the displaced, scaled contour (nearest crossing).
    double best = 1e9;
    for (size_t i = 0; i + 1 < chain.size(); ++i) {
      const Vector2d a = c + (1 + scale) * (chain[i] - c) + d;
      const Vector2d b = c + (1 + scale) * (chain[i + 1] - c) + d;
      const Vector2d ab = b - a;
      const double den = normal.x() * ab.y() - normal.y() * ab.x();
      if (std::abs(den) < 1e-12) continue;
      // p + u normal = a + v ab
      const Vector2d w = a - p;
      const double u = (w.x() * ab.y() - w.y() * ab.x()) / den;
      const double v = (w.x() * normal.y() - w.y() * normal.x()) / den;
      if (v >= 0 && v <= 1 && std::abs(u) < std::abs(best)) best = u;
    }
    measured.push_back(p + best * normal);
  }
  auto e = CompareContour(design, measured, /*closed=*/true);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_NEAR(e->offset_mm.x(), -0.3, 0.001);
  EXPECT_NEAR(e->offset_mm.y(), 0.2, 0.001);
  EXPECT_NEAR(e->scale_pct, 0.05, 0.001);
  // Eq. 22's matching at the corners, where the profiles' normals fan out: a few um.
  EXPECT_LT(e->local_max_mm, 0.01);
}

// A part of a contour (a gap of missing grooves longer than the clustering's tolerance splits
// one): the bottom and right sides of an 80 x 40 rectangle, moved by (0.3, -0.2) mm. Their
// normals fix the offset; the bending they cannot tell from it (each side's distance from the
// centroid is one number), so the offset alone is fitted and said so, never zeros.
TEST(Contours, APartOfAContourGivesItsOffsetAndSaysWhatIsLeft) {
  const Points2 design = Rectangle({100, 50}, 80, 40, 0.5);
  Points2 measured;
  for (const Vector2d& p : Rectangle({100, 50}, 80, 40, 0.05)) {
    const bool bottom = std::abs(p.y() - 30.0) < 1e-9, right = std::abs(p.x() - 140.0) < 1e-9;
    if ((bottom && p.x() > 62 && p.x() < 138) || (right && p.y() > 32 && p.y() < 68)) {
      measured.push_back(p + Vector2d(0.3, -0.2));
    }
  }
  auto e = CompareContour(design, measured, /*closed=*/true);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->fitted, "offset");
  EXPECT_NEAR(e->offset_mm.x(), -0.3, 1e-6);
  EXPECT_NEAR(e->offset_mm.y(), 0.2, 1e-6);
  // One side alone leaves the offset along it free: refused by name.
  Points2 one_side;
  for (const Vector2d& p : measured) {
    if (p.y() < 31) one_side.push_back(p);
  }
  auto refused = CompareContour(design, one_side, /*closed=*/true);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("do not determine"), std::string::npos);
}

}  // namespace
}  // namespace insitu::inspect
