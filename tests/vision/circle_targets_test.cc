// Tests of the spiral-filled circle target finder (seed 003 sec. 2.2) and the circle and
// ellipse fits.
//
// Images are synthetic: ellipses (a disc seen obliquely) rendered anti-aliased by 16 x 16
// supersampling of each pixel the edge passes through, on a background with a gradient (uneven
// room light), plus seeded Gaussian noise of known sigma, quantised to 8 or 12 bits in a buffer
// with a padded stride. Checks:
//  * the centre of the ellipse fitted to the sub-pixel edge is within a bound derived from the
//    noise and the number of edge points; seed 003's minimum enclosing circle is no better;
//  * a circle on a tilted plane, projected through a pinhole, is an ellipse whose centre is NOT
//    the image of the circle's centre (by the predicted amount); the edge mapped back onto the
//    plane and fitted with a circle recovers the true centre;
//  * blobs that are not targets come back as rejected, with where and why; bad input fails
//    with a clear message.
#include "insitu/vision/circle_targets.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace insitu::vision {
namespace {

// Gray values as doubles while rendering; View() quantises them into an 8- or 16-bit buffer
// whose rows are padded (so stride handling is exercised).
struct TestImage {
  int width = 0;
  int height = 0;
  int bit_depth = 8;
  std::vector<double> value;
  std::vector<uint8_t> bytes;

  TestImage(int w, int h, int depth) : width(w), height(h), bit_depth(depth), value(w * h, 0.0) {}

  double& at(int u, int v) { return value[static_cast<size_t>(v) * width + u]; }
  int max_value() const { return (1 << bit_depth) - 1; }

  // Adds `amplitude` times the fraction of each pixel inside the shape. `inside(x, y)` tells
  // whether an image point is inside; `near_edge(u, v)` whether pixel (u, v) may be cut by the
  // edge (those pixels are supersampled 16 x 16, the others take the value at their centre).
  void AddShape(const std::function<bool(double, double)>& inside,
                const std::function<bool(int, int)>& near_edge, double amplitude, int u0, int v0,
                int u1, int v1) {
    for (int v = std::max(0, v0); v <= std::min(height - 1, v1); ++v) {
      for (int u = std::max(0, u0); u <= std::min(width - 1, u1); ++u) {
        double fraction;
        if (near_edge(u, v)) {
          int in = 0;
          for (int sy = 0; sy < 16; ++sy) {
            for (int sx = 0; sx < 16; ++sx) {
              in += inside(u - 0.5 + (sx + 0.5) / 16.0, v - 0.5 + (sy + 0.5) / 16.0);
            }
          }
          fraction = in / 256.0;
        } else {
          fraction = inside(u, v) ? 1.0 : 0.0;
        }
        at(u, v) += amplitude * fraction;
      }
    }
  }

  // Ellipse of semi-axes a >= b, major axis at `angle` from the u axis, centred at (cu, cv).
  void AddEllipse(double cu, double cv, double a, double b, double angle, double amplitude) {
    const double c = std::cos(angle), s = std::sin(angle);
    const auto rho = [=](double x, double y) {
      const double p = (x - cu) * c + (y - cv) * s, q = -(x - cu) * s + (y - cv) * c;
      return std::sqrt(p * p / (a * a) + q * q / (b * b));
    };
    // Normalised radius rho changes by at most 1 / b per pixel of distance: pixels whose
    // centre is more than 1.5 px from the edge in that measure are wholly in or out.
    AddShape([=](double x, double y) { return rho(x, y) <= 1.0; },
             [=](int u, int v) { return std::abs(rho(u, v) - 1.0) * b < 1.5; }, amplitude,
             static_cast<int>(cu - a - 2), static_cast<int>(cv - a - 2),
             static_cast<int>(cu + a + 2), static_cast<int>(cv + a + 2));
  }

  void AddBackground(const std::function<double(int, int)>& level) {
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) at(u, v) += level(u, v);
    }
  }

  void AddNoise(double sigma, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n(0.0, sigma);
    for (double& x : value) x += n(rng);
  }

  ImageView View() {
    const int bpp = bit_depth > 8 ? 2 : 1;
    const size_t stride = static_cast<size_t>(width + 7) * bpp;
    bytes.assign(stride * height, 0);
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const int q = std::clamp(static_cast<int>(std::lround(at(u, v))), 0, max_value());
        if (bpp == 1) {
          bytes[v * stride + u] = static_cast<uint8_t>(q);
        } else {
          const uint16_t w = static_cast<uint16_t>(q);
          std::memcpy(&bytes[v * stride + 2 * u], &w, 2);
        }
      }
    }
    return ImageView{bytes.data(), width, height, stride, bit_depth};
  }
};

struct Truth {
  Eigen::Vector2d center;
  double a, b;
};

// The nearest target to a true centre (nullptr if none within 5 px).
const CircleTarget* Match(const std::vector<CircleTarget>& found, const Eigen::Vector2d& c) {
  const CircleTarget* best = nullptr;
  double d = 5.0;
  for (const CircleTarget& t : found) {
    if ((t.centroid_px - c).norm() < d) {
      d = (t.centroid_px - c).norm();
      best = &t;
    }
  }
  return best;
}

// 121 targets (11 x 11, as a field calibration marks them), each an ellipse about 30 x 26 px
// (a 2.5 mm disc seen at 31 deg with 80 um pixels) at a random sub-pixel centre and
// orientation, on a background that drifts from 30 to 70 gray levels across the frame; contrast
// C = 120 gray levels, noise sigma = 3 (x 16 for 12 bits).
class CircleTargetAccuracy : public ::testing::TestWithParam<int> {};

TEST_P(CircleTargetAccuracy, EdgeFitCentreIsNoiseLimitedAndBeatsTheMinimumEnclosingCircle) {
  const int depth = GetParam();
  const double gain = depth == 8 ? 1.0 : 16.0;
  const double contrast = 120 * gain, sigma = 3 * gain;
  TestImage image(720, 700, depth);
  image.AddBackground(
      [&](int u, int v) { return gain * (30.0 + 25.0 * u / 720 + 15.0 * v / 700); });
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Truth> truth;
  for (int j = 0; j < 11; ++j) {
    for (int i = 0; i < 11; ++i) {
      Truth t;
      t.center = Eigen::Vector2d(45 + 63 * i + unit(rng), 40 + 62 * j + unit(rng));
      t.a = 14.5 + unit(rng);
      t.b = t.a * (0.82 + 0.08 * unit(rng));
      image.AddEllipse(t.center.x(), t.center.y(), t.a, t.b, M_PI * unit(rng), contrast);
      truth.push_back(t);
    }
  }
  image.AddNoise(sigma, 11 + depth);
  std::vector<RejectedBlob> rejected;
  auto found = FindCircleTargets(image.View(), CircleTargetOptions{}, &rejected);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  EXPECT_EQ(found->size(), 121u);
  EXPECT_TRUE(rejected.empty()) << rejected.front().reason;
  // Raster order of the topmost pixel: rows of the grid come out in order.
  for (size_t k = 11; k < found->size(); ++k) {
    EXPECT_LT((*found)[k - 11].centroid_px.y(), (*found)[k].centroid_px.y());
  }

  // Bound on the edge-fit centre. Along a ray the edge point is where the profile crosses the
  // half level; its error is (value noise) / (slope of the profile).
  //  * Value noise: a bilinear sample averages up to 4 pixels with weights summing to 1, so
  //    its sigma is at most the pixel noise, sqrt(sigma^2 + q^2 / 12) with the quantisation
  //    step q = 1 gray level.
  //  * Slope: the anti-aliased edge spreads C over at most two pixel spacings of the linear
  //    interpolation (the edge pixel holds the covered fraction), so >= C / 2 per px.
  //    Hence sigma_noise <= 2 sqrt(sigma^2 + 1/12) / C = 0.05 px.
  //  * Pixel phase: with linear interpolation a sharp edge at e = k +- delta (delta in
  //    [0, 0.5]) is found at an error of -+(1 - 1/(1 + 2 delta) - delta) (1-D); over a
  //    uniform phase that is zero-mean with rms 0.062 px (max 0.086). Around an ellipse the
  //    phase runs through all values, so it acts as a further independent error per point.
  //  * A least-squares centre from N points spread evenly round the outline has sigma
  //    sigma_r sqrt(2 / N) per coordinate; neighbouring rays (one per pixel of perimeter)
  //    share half their pixels, so count N / 2 independent points: sigma_c =
  //    sqrt(sigma_noise^2 + 0.062^2) * 2 / sqrt(N) ~ 0.017 px for N ~ 90.
  // The rms of the 2-D error over 121 targets must stay below sqrt(2) sigma_c, the largest
  // below 4 sigma_c (a 2-D Gaussian exceeds that with probability e^-8 = 3e-4 per target).
  double se_edge = 0, se_mec = 0, se_centroid = 0, worst_edge = 0, bound_sum = 0;
  for (const Truth& t : truth) {
    const CircleTarget* f = Match(*found, t.center);
    ASSERT_NE(f, nullptr) << "target at " << t.center.transpose() << " not found";
    auto ellipse = FitEllipse(f->edge_px);
    ASSERT_TRUE(ellipse.ok()) << ellipse.status().ToString();
    EXPECT_NEAR(ellipse->semi_major, t.a, 0.1);
    EXPECT_NEAR(ellipse->semi_minor, t.b, 0.1);
    EXPECT_GE(f->edge_px.size(), 0.9 * f->edge_rays);
    EXPECT_NEAR(f->plateau - f->background, contrast, 4 * sigma);
    const double n = static_cast<double>(f->edge_px.size());
    const double sigma_noise = 2.0 * std::sqrt(sigma * sigma + 1.0 / 12.0) / contrast;
    const double sigma_c =
        std::sqrt(sigma_noise * sigma_noise + 0.062 * 0.062) * 2.0 / std::sqrt(n);
    const double e = (ellipse->center - t.center).norm();
    EXPECT_LE(e, 4.0 * sigma_c) << "target at " << t.center.transpose();
    worst_edge = std::max(worst_edge, e);
    se_edge += e * e;
    bound_sum += 2.0 * sigma_c * sigma_c;
    se_mec += (f->mec_center_px - t.center).squaredNorm();
    se_centroid += (f->centroid_px - t.center).squaredNorm();
  }
  const double rms_edge = std::sqrt(se_edge / truth.size());
  const double rms_mec = std::sqrt(se_mec / truth.size());
  const double rms_bound = std::sqrt(bound_sum / truth.size());
  std::printf(
      "%d-bit: centre rms error: edge fit %.4f px (max %.4f, bound %.4f), minimum "
      "enclosing circle %.4f px, area centroid %.4f px\n",
      depth, rms_edge, worst_edge, rms_bound, rms_mec, std::sqrt(se_centroid / truth.size()));
  EXPECT_LE(rms_edge, rms_bound);
  // Seed 003's estimator rests on the two or three outermost contour pixels: never better.
  EXPECT_GE(rms_mec, rms_edge);
}

INSTANTIATE_TEST_SUITE_P(Depths, CircleTargetAccuracy, ::testing::Values(8, 12));

// A pinhole camera looking at a plane tilted by alpha about the camera's x axis, the plane's
// point on the optical axis at distance D. Points of the plane are o + s e1 + t e2.
struct TiltedView {
  double f_px = 2000.0;
  Eigen::Vector2d principal{400.0, 300.0};
  double distance = 200.0;  // mm
  double alpha = 40.0 * M_PI / 180.0;
  Eigen::Vector3d o() const { return {0, 0, distance}; }
  Eigen::Vector3d e1() const { return {1, 0, 0}; }
  Eigen::Vector3d e2() const { return {0, std::cos(alpha), std::sin(alpha)}; }
  Eigen::Vector2d Project(const Eigen::Vector2d& st) const {
    const Eigen::Vector3d p = o() + st.x() * e1() + st.y() * e2();
    return principal + f_px * p.head<2>() / p.z();
  }
  // The pixel's ray met with the plane, in plane coordinates (s, t).
  Eigen::Vector2d ToPlane(const Eigen::Vector2d& px) const {
    const Eigen::Vector3d ray(((px - principal) / f_px).x(), ((px - principal) / f_px).y(), 1.0);
    const Eigen::Vector3d n = e1().cross(e2());
    const Eigen::Vector3d p = ray * (n.dot(o()) / n.dot(ray));
    return {(p - o()).dot(e1()), (p - o()).dot(e2())};
  }
};

// The image of a circle is an ellipse, but the ellipse's centre is not the image of the
// circle's centre. On the axis of a view tilted by alpha, the circle's diameter along the tilt
// runs from depth D - R sin(alpha) to D + R sin(alpha); by the view's mirror symmetry the
// ellipse's centre is the midpoint of that diameter's image, which lies
// -f R^2 sin(alpha) cos(alpha) / (D^2 - R^2 sin^2(alpha)) px from the image of the centre:
// toward the near side, which looks bigger. On the plane it is exactly R^2 sin(alpha) / D
// (the pole of the line where the plane meets the plane through the camera's centre parallel to
// the sensor, which lies D / sin(alpha) away): 2.3 um for seed 003's kind of target
// (R = 1.25 mm) from the side camera (D = 350 mm, alpha = 31 deg), as large as the accuracy
// asked for. Mapping the edge onto the plane first and fitting a circle there removes it.
TEST(CircleTargetPerspective, EllipseCentreIsNotTheImageOfTheCircleCentre) {
  TiltedView view;
  const double r = 4.0;  // mm, so the effect is large against the test's tolerances
  std::vector<Eigen::Vector2d> image_points, plane_points;
  for (int k = 0; k < 720; ++k) {
    const double phi = 2.0 * M_PI * k / 720;
    image_points.push_back(view.Project(r * Eigen::Vector2d(std::cos(phi), std::sin(phi))));
  }
  auto ellipse = FitEllipse(image_points);
  ASSERT_TRUE(ellipse.ok()) << ellipse.status().ToString();
  EXPECT_LT(ellipse->rms_residual, 1e-9);  // exactly an ellipse
  const Eigen::Vector2d centre_image = view.Project({0, 0});
  const double sa = std::sin(view.alpha), ca = std::cos(view.alpha);
  const double predicted_px =
      -view.f_px * r * r * sa * ca / (view.distance * view.distance - r * r * sa * sa);
  EXPECT_NEAR(ellipse->center.x() - centre_image.x(), 0.0, 1e-9);
  EXPECT_NEAR(ellipse->center.y() - centre_image.y(), predicted_px, 1e-6);
  const Eigen::Vector2d ellipse_centre_on_plane = view.ToPlane(ellipse->center);
  EXPECT_NEAR(ellipse_centre_on_plane.x(), 0.0, 1e-9);
  EXPECT_NEAR(ellipse_centre_on_plane.y(), -r * r * sa / view.distance, 1e-9);
  std::printf(
      "perspective: ellipse centre %.4f px from the image of the circle's centre "
      "(%.1f um on the plane)\n",
      predicted_px, 1e3 * ellipse_centre_on_plane.norm());

  // Rectified: the edge on the plane is the circle itself.
  for (const Eigen::Vector2d& p : image_points) plane_points.push_back(view.ToPlane(p));
  auto circle = FitCircle(plane_points);
  ASSERT_TRUE(circle.ok()) << circle.status().ToString();
  EXPECT_LT(circle->center.norm(), 1e-9);
  EXPECT_NEAR(circle->radius, r, 1e-9);

  // The same through the finder, on a rendered image: the disc is drawn by sending each
  // subsample's ray to the plane. The rectified edge fit finds the centre; the seed's
  // minimum enclosing circle (an ellipse's is centred on the ellipse) and the ellipse fit
  // carry the perspective offset.
  TestImage image(800, 600, 8);
  image.AddBackground([](int, int) { return 40.0; });
  const auto rho = [&](double x, double y) { return view.ToPlane({x, y}).norm(); };
  const double px_per_mm_max = view.f_px / (view.distance - r * sa);
  image.AddShape([&](double x, double y) { return rho(x, y) <= r; },
                 [&](int u, int v) { return std::abs(rho(u, v) - r) * px_per_mm_max < 2.5; }, 150.0,
                 330, 230, 470, 370);
  image.AddNoise(3.0, 5);
  CircleTargetOptions options;
  options.max_diameter_px = 200;
  auto found = FindCircleTargets(image.View(), options);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  ASSERT_EQ(found->size(), 1u);
  const CircleTarget& t = found->front();
  std::vector<Eigen::Vector2d> rectified;
  for (const Eigen::Vector2d& p : t.edge_px) rectified.push_back(view.ToPlane(p));
  auto fit = FitCircle(rectified);
  ASSERT_TRUE(fit.ok());
  auto image_ellipse = FitEllipse(t.edge_px);
  ASSERT_TRUE(image_ellipse.ok());
  // Noise bound as in the accuracy test, with a sharp edge of C = 150, sigma = 3 and N points:
  // sigma_c = sqrt((2 sqrt(9 + 1/12) / 150)^2 + 0.062^2) * 2 / sqrt(N) px, at most
  // 1 / (f / (D - R sin(alpha))) mm per px on the plane (the finest scale of the view);
  // allowed: 4 sigma_c.
  const double n = static_cast<double>(t.edge_px.size());
  const double sigma_c_px =
      std::hypot(2.0 * std::sqrt(9.0 + 1.0 / 12.0) / 150.0, 0.062) * 2.0 / std::sqrt(n);
  const double mm_per_px = (view.distance + r * sa) / view.f_px / ca;  // coarsest, along the tilt
  const double tolerance_mm = 4.0 * sigma_c_px * mm_per_px;
  const double offset_mm = r * r * sa / view.distance;
  EXPECT_LT(fit->center.norm(), tolerance_mm);
  EXPECT_NEAR(fit->radius, r, 2 * tolerance_mm);
  const Eigen::Vector2d ellipse_on_plane = view.ToPlane(image_ellipse->center);
  const Eigen::Vector2d mec_on_plane = view.ToPlane(t.mec_center_px);
  EXPECT_NEAR(ellipse_on_plane.y(), -offset_mm, tolerance_mm);
  EXPECT_GT((mec_on_plane - fit->center).norm(), 0.5 * offset_mm);
  std::printf(
      "rendered: rectified circle centre %.1f um off, image ellipse centre %.1f um, "
      "minimum enclosing circle %.1f um (predicted offset %.1f um, tolerance %.1f um)\n",
      1e3 * fit->center.norm(), 1e3 * ellipse_on_plane.norm(), 1e3 * mec_on_plane.norm(),
      1e3 * offset_mm, 1e3 * tolerance_mm);
}

TEST(CircleTargets, RejectedBlobsSayWhereAndWhy) {
  TestImage image(400, 300, 8);
  image.AddBackground([](int, int) { return 30.0; });
  image.AddEllipse(60, 60, 12, 11, 0.3, 120);  // a good target
  image.AddEllipse(200, 60, 3, 3, 0, 120);     // 6 px: too small
  image.AddEllipse(320, 150, 55, 50, 0, 120);  // 105 px: too large
  image.AddShape([](double x, double y) { return x >= 40 && x < 110 && y >= 140 && y < 147; },
                 [](int, int) { return false; }, 120, 30, 130, 120, 160);  // a scratch
  // A "Pac-man": a disc with a quarter cut out (solidity 0.82).
  image.AddShape(
      [](double x, double y) {
        const double dx = x - 60, dy = y - 230;
        return dx * dx + dy * dy <= 144 && !(dx > 0 && dy < 0);
      },
      [](int, int) { return true; }, 120, 40, 210, 80, 250);
  image.AddEllipse(150, 230, 12, 12, 0, 20);  // faint
  image.AddEllipse(3, 150, 12, 12, 0, 120);   // cut by the border
  image.AddNoise(1.0, 3);
  CircleTargetOptions options;
  options.min_contrast_fraction = 0.1;  // 25.5 gray levels: the faint one (20) fails
  std::vector<RejectedBlob> rejected;
  auto found = FindCircleTargets(image.View(), options, &rejected);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  ASSERT_EQ(found->size(), 1u);
  EXPECT_NEAR(found->front().centroid_px.x(), 60, 0.5);
  const auto reason_near = [&](double u, double v) -> std::string {
    for (const RejectedBlob& r : rejected) {
      if ((r.center_px - Eigen::Vector2d(u, v)).norm() < 8) return r.reason;
    }
    return "(not listed)";
  };
  EXPECT_NE(reason_near(200, 60).find("too small"), std::string::npos) << reason_near(200, 60);
  EXPECT_NE(reason_near(320, 150).find("too large"), std::string::npos) << reason_near(320, 150);
  EXPECT_NE(reason_near(75, 143).find("elongated"), std::string::npos) << reason_near(75, 143);
  EXPECT_NE(reason_near(58, 232).find("solid"), std::string::npos) << reason_near(58, 232);
  EXPECT_NE(reason_near(150, 230).find("contrast"), std::string::npos) << reason_near(150, 230);
  EXPECT_NE(reason_near(6, 150).find("border"), std::string::npos) << reason_near(6, 150);
  EXPECT_EQ(rejected.size(), 6u);
}

TEST(CircleTargets, MalformedInputGivesClearErrors) {
  TestImage image(64, 64, 8);
  ImageView view = image.View();
  const CircleTargetOptions good;
  const auto message_of = [](const Status& s) { return s.ToString(); };

  ImageView empty;
  auto r = FindCircleTargets(empty, good);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(message_of(r.status()).find("empty"), std::string::npos) << message_of(r.status());

  ImageView odd = view;
  odd.bit_depth = 9;
  r = FindCircleTargets(odd, good);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(message_of(r.status()).find("bit depth 9"), std::string::npos);
  odd.bit_depth = 32;
  EXPECT_EQ(FindCircleTargets(odd, good).status().code(), StatusCode::kInvalidArgument);

  ImageView short_rows = view;
  short_rows.bit_depth = 12;  // 2 bytes per pixel: the 8-bit buffer's stride is too short
  short_rows.stride_bytes = 64;
  r = FindCircleTargets(short_rows, good);
  EXPECT_NE(message_of(r.status()).find("stride"), std::string::npos) << message_of(r.status());

  const std::vector<std::pair<std::function<void(CircleTargetOptions*)>, std::string>> bad = {
      {[](CircleTargetOptions* o) { o->min_diameter_px = 0; }, "min_diameter_px"},
      {[](CircleTargetOptions* o) { o->max_diameter_px = 5; }, "max_diameter_px"},
      {[](CircleTargetOptions* o) { o->min_contrast_fraction = 0; }, "min_contrast_fraction"},
      {[](CircleTargetOptions* o) { o->min_solidity = 1.5; }, "min_solidity"},
      {[](CircleTargetOptions* o) { o->min_axis_ratio = -1; }, "min_axis_ratio"},
      {[](CircleTargetOptions* o) { o->edge_rays = -1; }, "edge_rays"},
  };
  for (const auto& [change, field] : bad) {
    CircleTargetOptions o;
    change(&o);
    EXPECT_FALSE(o.Validate().ok()) << field;
    r = FindCircleTargets(view, o);
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << field;
    EXPECT_NE(message_of(r.status()).find(field), std::string::npos) << message_of(r.status());
  }

  // A blank frame is not an error: no targets.
  r = FindCircleTargets(view, good);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->empty());
}

TEST(CircleFitting, RecoversCircleAndEllipseAndRefusesDegenerateInput) {
  // A 90 degree arc of a circle with a deterministic radial wobble: the fit must find the
  // circle the wobble averages to (a partial arc is where Kasa's fit is biased; Taubin + the
  // geometric refinement are not).
  std::vector<Eigen::Vector2d> arc;
  for (int k = 0; k <= 90; ++k) {
    const double t = k * M_PI / 180.0;
    const double r = 50.0 + 0.01 * std::cos(7.0 * t * 4);
    arc.emplace_back(1000.0 + r * std::cos(t), 800.0 + r * std::sin(t));
  }
  auto c = FitCircle(arc);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_NEAR(c->center.x(), 1000.0, 0.02);
  EXPECT_NEAR(c->center.y(), 800.0, 0.02);
  EXPECT_NEAR(c->radius, 50.0, 0.02);
  EXPECT_NEAR(c->rms_residual, 0.01 / std::sqrt(2.0), 0.002);

  std::vector<Eigen::Vector2d> ellipse;
  for (int k = 0; k < 40; ++k) {
    const double t = 2 * M_PI * k / 40;
    const Eigen::Vector2d local(20 * std::cos(t), 12 * std::sin(t));
    ellipse.push_back(Eigen::Vector2d(300, -40) + Eigen::Rotation2Dd(0.6) * local);
  }
  auto e = FitEllipse(ellipse);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_NEAR(e->center.x(), 300, 1e-9);
  EXPECT_NEAR(e->center.y(), -40, 1e-9);
  EXPECT_NEAR(e->semi_major, 20, 1e-9);
  EXPECT_NEAR(e->semi_minor, 12, 1e-9);
  EXPECT_NEAR(e->angle_rad, 0.6, 1e-9);

  EXPECT_EQ(FitCircle({{0, 0}, {1, 1}}).status().code(), StatusCode::kInvalidArgument);
  auto line = FitCircle({{0, 0}, {1, 1}, {2, 2}, {3, 3}});
  EXPECT_EQ(line.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(line.status().message().find("line"), std::string::npos);
  EXPECT_FALSE(FitCircle({{0, 0}, {1, NAN}, {2, 0}}).ok());
  EXPECT_EQ(FitEllipse({{0, 0}, {1, 0}, {0, 1}, {1, 1}}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_FALSE(FitEllipse({{0, 0}, {1, 1}, {2, 2}, {3, 3}, {4, 4}, {5, 5}}).ok());
}

}  // namespace
}  // namespace insitu::vision
