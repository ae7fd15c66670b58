#include "insitu/inspect/groove.h"

#include <ceres/tiny_solver.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "insitu/core/robust.h"

namespace insitu::inspect {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Point {
  double x, z;
};

// A robust standard deviation of values about zero (1.4826 times their median absolute
// value), never below `floor`.
double RobustSigma(const std::vector<double>& v, double floor) {
  return std::max(kMadToSigma * MedianAbsDeviationFrom(v, 0.0), floor);
}

// Each value's departure from the median of its neighbours within two places, itself among them
// when `with_self`.
std::vector<double> FromLocalMedian(const std::vector<double>& v, bool with_self) {
  const int n = static_cast<int>(v.size());
  std::vector<double> out(n), near;
  for (int i = 0; i < n; ++i) {
    near.clear();
    for (int j = std::max(0, i - 2); j <= std::min(n - 1, i + 2); ++j) {
      if (with_self || j != i) near.push_back(v[j]);
    }
    out[i] = v[i] - MedianInPlace(near);
  }
  return out;
}

// Least-squares line z = k x + b.
bool FitLine(const std::vector<Point>& p, double* k, double* b) {
  double sx = 0, sz = 0, sxx = 0, sxz = 0;
  for (const Point& q : p) {
    sx += q.x;
    sz += q.z;
    sxx += q.x * q.x;
    sxz += q.x * q.z;
  }
  const double n = static_cast<double>(p.size());
  const double den = n * sxx - sx * sx;
  if (p.size() < 2 || !(std::abs(den) > 0)) return false;
  *k = (n * sxz - sx * sz) / den;
  *b = (sz - *k * sx) / n;
  return true;
}

// The template of eq. 11 and its residuals z - T(x) over the levelled points, for TinySolver.
// Parameters (x0, z0, D, w) with D = d tanh(alpha w / 4), the template's deepest point below its
// surface: in eq. 11's own d, depth and width are strongly correlated when the edges overlap
// (d grows as w shrinks at the same depth) and Levenberg-Marquardt crawls along that valley; in
// D they are nearly independent.
class Template {
 public:
  using Scalar = double;
  enum { NUM_RESIDUALS = Eigen::Dynamic, NUM_PARAMETERS = 4 };

  Template(const std::vector<Point>& p, double alpha) : p_(p), alpha_(alpha) {}
  int NumResiduals() const { return static_cast<int>(p_.size()); }

  // The width enters as its logarithm (q[3] = ln w): every step the solver tries is a groove of
  // positive width, so the residuals are always defined (TinySolver does not handle a cost
  // function that declines a step).
  bool operator()(const double* q, double* residuals, double* jacobian) const {
    const int n = NumResiduals();
    const double x0 = q[0], z0 = q[1], depth = q[2], w = std::exp(std::clamp(q[3], -30.0, 30.0));
    const double t = std::max(std::tanh(0.25 * alpha_ * w), 1e-300);
    const double d = depth / t;
    // d d / d w at fixed depth.
    const double dd_dw = -depth * 0.25 * alpha_ * (1.0 - t * t) / (t * t);
    for (int i = 0; i < n; ++i) {
      const double a = alpha_ * (p_[i].x - x0 - 0.25 * w);
      const double b = alpha_ * (p_[i].x - x0 + 0.25 * w);
      const double ta = std::tanh(a), tb = std::tanh(b);
      residuals[i] = p_[i].z - (z0 + 0.5 * d * (ta - tb));
      if (jacobian != nullptr) {
        const double sa = 1.0 - ta * ta, sb = 1.0 - tb * tb;
        // Column-major, n rows: d residual / d parameter = -d T / d parameter.
        jacobian[0 * n + i] = -0.5 * d * alpha_ * (sb - sa);
        jacobian[1 * n + i] = -1.0;
        jacobian[2 * n + i] = -0.5 * (ta - tb) / t;
        jacobian[3 * n + i] = w * (0.125 * d * alpha_ * (sa + sb) - 0.5 * (ta - tb) * dd_dw);
      }
    }
    return true;
  }

 private:
  const std::vector<Point>& p_;
  double alpha_;
};

// The template at x for parameters (x0, z0, D, w): the width itself, not its logarithm.
double TemplateValue(double alpha, const Eigen::Vector4d& q, double x) {
  const double d = q[2] / std::tanh(0.25 * alpha * q[3]);
  return q[1] + 0.5 * d *
                    (std::tanh(alpha * (x - q[0] - 0.25 * q[3])) -
                     std::tanh(alpha * (x - q[0] + 0.25 * q[3])));
}

// Fits the template to `p` from `q`; false when the solver fails or the result is no groove.
bool Solve(const std::vector<Point>& p, double alpha, int max_iterations, Eigen::Vector4d* q,
           int* iterations) {
  Template f(p, alpha);
  ceres::TinySolver<Template> solver;
  solver.options.max_num_iterations = max_iterations;
  solver.options.function_tolerance = 1e-10;
  solver.options.parameter_tolerance = 1e-10;
  if (!((*q)[3] > 0)) return false;
  Eigen::Vector4d u = *q;
  u[3] = std::log((*q)[3]);
  const auto summary = solver.Solve(f, &u);
  *iterations += summary.iterations;
  if (summary.status == ceres::TinySolver<Template>::HIT_MAX_ITERATIONS) return false;
  *q = u;
  (*q)[3] = std::exp(u[3]);
  return q->allFinite() && (*q)[2] > 0 && (*q)[3] > 0;
}

// Where the fitted template (levelled) is half its depth below its surface on the side `sign`
// (-1 left, +1 right) of its centre: bisection, the template falling monotonically from its
// centre outward.
double TemplateHalfDepthX(double alpha, const Eigen::Vector4d& q, int sign) {
  const double target = q[1] - 0.5 * q[2];
  double in = 0.0, out = q[3] + 10.0 / alpha;  // offsets from the centre
  for (int it = 0; it < 60; ++it) {
    const double mid = 0.5 * (in + out);
    (TemplateValue(alpha, q, q[0] + sign * mid) < target ? in : out) = mid;
  }
  return q[0] + sign * 0.5 * (in + out);
}

// The least-squares parabola z = a + b x + c x^2 through `p` (x taken about x_ref); false with
// fewer than 3 points or a singular system.
bool FitParabola(const std::vector<Point>& p, double x_ref, Eigen::Vector3d* abc) {
  if (p.size() < 3) return false;
  Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
  Eigen::Vector3d atz = Eigen::Vector3d::Zero();
  for (const Point& q : p) {
    const double u = q.x - x_ref;
    const Eigen::Vector3d row(1.0, u, u * u);
    ata += row * row.transpose();
    atz += row * q.z;
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(ata);
  if (lu.rank() < 3) return false;
  *abc = lu.solve(atz);
  return abc->allFinite();
}

}  // namespace

Status GrooveOptions::Validate() const {
  if (!(expected_width_mm > 0)) return InvalidArgument("expected_width_mm must be > 0");
  if (!(window_mm >= 0)) return InvalidArgument("window_mm must be >= 0");
  if (!(alpha_per_mm > 0)) return InvalidArgument("alpha_per_mm must be > 0");
  if (!(outlier_sigmas > 0)) return InvalidArgument("outlier_sigmas must be > 0");
  if (max_iterations < 1) return InvalidArgument("max_iterations must be >= 1");
  if (!(z_resolution_mm > 0)) return InvalidArgument("z_resolution_mm must be > 0");
  if (!(z_min_mm < z_max_mm)) return InvalidArgument("z_min_mm must be below z_max_mm");
  return Status::Ok();
}

Groove FitGroove(const Profile& profile, const GrooveOptions& o) {
  Groove g;
  const auto fail = [&g](std::string why) {
    g.ok = false;
    g.why = std::move(why);
    return g;
  };
  std::vector<Point> valid;
  valid.reserve(profile.z_mm.size());
  const bool cut = std::isfinite(o.expected_x_mm) && o.window_mm > 0;
  for (size_t i = 0; i < profile.z_mm.size(); ++i) {
    const double z = profile.z_mm[i];
    const double x = profile.x_start_mm + profile.dx_mm * static_cast<double>(i);
    if (!std::isfinite(z) || z < o.z_min_mm || z > o.z_max_mm) continue;
    if (cut && std::abs(x - o.expected_x_mm) > o.window_mm) continue;
    valid.push_back({x, z});
  }
  constexpr int kMinPoints = 12;
  if (static_cast<int>(valid.size()) < kMinPoints) {
    return fail(std::to_string(valid.size()) + " valid points");
  }

  // Spikes: a point departing from the median of its five neighbours by more than
  // outlier_sigmas robust deviations (the groove's flanks are straight, so a median follows
  // them; at its bottom it does not quite, and a point rejected there comes back below once it
  // agrees with the fitted template).
  const int n = static_cast<int>(valid.size());
  std::vector<double> z(n);
  for (int i = 0; i < n; ++i) z[i] = valid[i].z;
  const std::vector<double> dev = FromLocalMedian(z, true);
  const double sigma = RobustSigma(dev, o.z_resolution_mm);
  std::vector<Point> kept;
  std::vector<bool> spike(n);
  kept.reserve(n);
  for (int i = 0; i < n; ++i) {
    spike[i] = std::abs(dev[i]) > o.outlier_sigmas * sigma;
    if (!spike[i]) kept.push_back(valid[i]);
  }
  g.outliers = n - static_cast<int>(kept.size());

  // Levelling (eq. 12-13): the deepest point below a line through everything, the groove cut
  // out +-expected_width about it, the surface line through the rest.
  double k1 = 0, b1 = 0;
  if (!FitLine(kept, &k1, &b1)) return fail("no line through the profile");
  const Point* deepest = &kept[0];
  double below = -std::numeric_limits<double>::infinity();
  for (const Point& p : kept) {
    const double d = (k1 * p.x + b1 - p.z) / std::sqrt(1.0 + k1 * k1);
    if (d > below) {
      below = d;
      deepest = &p;
    }
  }
  const Point bottom = *deepest;
  if (o.window_mm > 0) {
    std::vector<Point> in;
    for (const Point& p : kept) {
      if (std::abs(p.x - bottom.x) <= o.window_mm) in.push_back(p);
    }
    kept.swap(in);
  }
  std::vector<Point> surface;
  int left = 0, right = 0;
  for (const Point& p : kept) {
    if (std::abs(p.x - bottom.x) >= o.expected_width_mm) {
      surface.push_back(p);
      (p.x < bottom.x ? left : right) += 1;
    }
  }
  if (left < 2 || right < 2) {
    return fail("too little surface beside the groove (" + std::to_string(left) + " points left, " +
                std::to_string(right) + " right)");
  }
  double k2 = 0, b2 = 0;
  if (!FitLine(surface, &k2, &b2)) return fail("no surface line");
  const double theta = std::atan(k2);
  const double c = std::cos(theta), s = std::sin(theta);
  const auto level = [c, s](const Point& p) {
    return Point{c * p.x + s * p.z, -s * p.x + c * p.z};
  };
  std::vector<Point> levelled;
  levelled.reserve(kept.size());
  for (const Point& p : kept) levelled.push_back(level(p));
  double z_surface = 0;
  for (const Point& p : surface) z_surface += level(p).z;
  z_surface /= static_cast<double>(surface.size());
  const Point lb = level(bottom);
  const double depth0 = z_surface - lb.z;
  double ss_surface = 0;
  for (const Point& p : surface) {
    const double r = p.z - (k2 * p.x + b2);
    ss_surface += r * r;
  }
  // A groove stands out of the surface's scatter: its bottom deeper than 6 of the surface's
  // standard deviations (over ~100 surface points, noise reaches ~3 of them).
  const double sd_surface = std::sqrt(ss_surface / static_cast<double>(surface.size()));
  if (!(depth0 > 6.0 * sd_surface)) {
    char buf[160];
    std::snprintf(buf, sizeof buf,
                  "no groove: the deepest point is %.1f um below the surface, whose own scatter "
                  "is %.1f um",
                  1e3 * depth0, 1e3 * sd_surface);
    return fail(buf);
  }
  // The width where the profile is below half the depth is half the template's w.
  double lo = lb.x, hi = lb.x;
  for (const Point& p : levelled) {
    if (p.z < z_surface - 0.5 * depth0) {
      lo = std::min(lo, p.x);
      hi = std::max(hi, p.x);
    }
  }
  const double w0 = hi > lo ? 2.0 * (hi - lo) : o.expected_width_mm;

  Eigen::Vector4d q(lb.x, z_surface, depth0, w0);
  if (!Solve(levelled, o.alpha_per_mm, o.max_iterations, &q, &g.iterations)) {
    return fail("the template's fit did not converge to a groove");
  }
  // A point the spike filter took comes back when it agrees with the fitted template or lies
  // on the line of the two points beside it on either side (a groove's bottom, where the
  // median of its neighbours does not follow the profile: a V's tip is on both its flanks'
  // lines, a spike on neither), and the fit runs once more. Points the filter kept stay:
  // where the template misses the groove's shape (a laser-cut flank is no tanh), its misfit
  // is the template's, not the points'.
  {
    std::vector<Point> all, agree;
    std::vector<bool> was_spike;
    const auto on_a_side = [&](int i) {
      const double limit = o.outlier_sigmas * sigma;
      for (int dir : {-1, 1}) {
        const int a = i + dir, b = i + 2 * dir;
        if (b < 0 || b >= n || spike[a] || spike[b]) continue;
        const double t = (valid[i].x - valid[a].x) / (valid[a].x - valid[b].x);
        if (std::abs(valid[i].z - (valid[a].z + t * (valid[a].z - valid[b].z))) <= limit) {
          return true;
        }
      }
      return false;
    };
    for (int i = 0; i < n; ++i) {
      if (o.window_mm > 0 && std::abs(valid[i].x - bottom.x) > o.window_mm) continue;
      all.push_back(level(valid[i]));
      was_spike.push_back(spike[i] && !on_a_side(i));
    }
    std::vector<double> r;
    for (size_t i = 0; i < all.size(); ++i) {
      if (!was_spike[i]) r.push_back(all[i].z - TemplateValue(o.alpha_per_mm, q, all[i].x));
    }
    const double sr = RobustSigma(r, o.z_resolution_mm);
    for (size_t i = 0; i < all.size(); ++i) {
      const double ri = all[i].z - TemplateValue(o.alpha_per_mm, q, all[i].x);
      if (!was_spike[i] || std::abs(ri) <= o.outlier_sigmas * sr) agree.push_back(all[i]);
    }
    g.outliers = static_cast<int>(all.size() - agree.size());  // within the window
    levelled.swap(agree);
    if (static_cast<int>(levelled.size()) < kMinPoints) return fail("too few points agree");
    if (!Solve(levelled, o.alpha_per_mm, o.max_iterations, &q, &g.iterations)) {
      return fail("the template's fit did not converge to a groove");
    }
  }
  double ss = 0;
  for (const Point& p : levelled) {
    const double r = p.z - TemplateValue(o.alpha_per_mm, q, p.x);
    ss += r * r;
  }
  // The groove measured from its own points, the template placing it (a laser-cut groove is
  // no tanh step: its flanks follow the beam's profile, and the template's shape would bias
  // what it reports by its misfit).
  // - Depth: the deepest point, a parabola through the points in the groove's lowest tenth
  //   (the bottom of a laser-cut groove is smooth: the beam's profile, or the metal under a
  //   film cut through; over a wider band a parabola through a flat floor and the start of
  //   its flanks dips below the floor), below the template's surface; a fifth when the tenth
  //   holds fewer than three points.
  // - The half-depth points: on each flank a parabola through the points about where it
  //   crosses half the depth, and where that parabola does; where the sensor saw no points on
  //   one side of the crossing, the template's own half-depth point.
  // - Centre: midway between them. Width: twice their distance along the surface (seed 002's
  //   w, the opening of a V-groove of that half-depth width; the template's w when its edges
  //   do not overlap).
  // The surface: the levelled line through the points beside the groove (the template's z0
  // leans toward wherever its shape misses the groove's).
  const double z0 = z_surface;
  double depth = q[2];
  {
    std::vector<Point> low;
    for (double band : {0.1, 0.2}) {
      low.clear();
      for (const Point& p : levelled) {
        if (z0 - p.z >= (1.0 - band) * q[2]) low.push_back(p);
      }
      if (low.size() >= 3) break;
    }
    Eigen::Vector3d abc;
    double lo_x = std::numeric_limits<double>::infinity(), hi_x = -lo_x;
    for (const Point& p : low) lo_x = std::min(lo_x, p.x), hi_x = std::max(hi_x, p.x);
    if (FitParabola(low, q[0], &abc) && abc[2] > 0) {
      const double u = -abc[1] / (2.0 * abc[2]);  // the vertex, when it lies among the points
      if (q[0] + u >= lo_x && q[0] + u <= hi_x) depth = z0 - (abc[0] + abc[1] * u + abc[2] * u * u);
    } else if (low.size() >= 3) {
      // A flat floor (or one the fit cannot bend): the mean of its points.
      double m = 0;
      for (const Point& p : low) m += p.z;
      depth = z0 - m / static_cast<double>(low.size());
    }
  }
  double half_x[2];
  for (int side = 0; side < 2; ++side) {
    const int sign = side == 0 ? -1 : 1;
    // The flank's points from the bottom outward, between a tenth and nine tenths of the depth.
    std::vector<Point> flank;
    for (const Point& p : levelled) {
      const double d = z0 - p.z;
      if ((p.x - q[0]) * sign > 0 && d >= 0.1 * depth && d <= 0.9 * depth) flank.push_back(p);
    }
    std::sort(flank.begin(), flank.end(), [sign](const Point& a, const Point& b) {
      return (a.x - b.x) * sign < 0;
    });
    // Where the flank passes half the depth: a parabola through its points between a quarter
    // and three quarters of the depth (a gentle flank has many, and they average its noise),
    // or, where there are fewer than four (a steep flank), through the two on each side of the
    // crossing; its root between the two that straddle it.
    size_t cross = 0;
    while (cross < flank.size() && z0 - flank[cross].z >= 0.5 * depth) ++cross;
    std::vector<Point> near;
    for (const Point& p : flank) {
      const double d = z0 - p.z;
      if (d >= 0.25 * depth && d <= 0.75 * depth) near.push_back(p);
    }
    if (near.size() < 4) {
      near.clear();
      for (size_t i = cross >= 2 ? cross - 2 : 0; i < std::min(flank.size(), cross + 2); ++i) {
        near.push_back(flank[i]);
      }
    }
    Eigen::Vector3d abc;
    const double zh = z0 - 0.5 * depth;
    if (cross > 0 && cross < flank.size()) {
      // The crossing between the two points that straddle it: first where the straight line
      // through them crosses, then, where a parabola through the points about it has a root
      // within a spacing of them (the noisy pair need not straddle the smoothed flank), that
      // root (bisection: the parabola is monotonic over so short a bracket or it is not taken).
      const Point& in = flank[cross - 1];
      const Point& out = flank[cross];
      double x = in.x + (zh - in.z) / (out.z - in.z) * (out.x - in.x);
      if (near.size() >= 3 && FitParabola(near, out.x, &abc)) {
        const auto f = [&](double xx) {
          const double u = xx - out.x;
          return abc[0] + abc[1] * u + abc[2] * u * u - zh;
        };
        const double step = out.x - in.x;
        double lo = in.x - step, hi = out.x + step;
        if (f(lo) * f(hi) < 0) {
          for (int it = 0; it < 60; ++it) {
            const double mid = 0.5 * (lo + hi);
            (f(lo) * f(mid) <= 0 ? hi : lo) = mid;
          }
          x = 0.5 * (lo + hi);
        }
      }
      half_x[side] = x;
    } else {
      half_x[side] = TemplateHalfDepthX(o.alpha_per_mm, q, sign);
    }
  }
  // The centre in the profile's frame: midway between the two half-depth points there. (A
  // groove cut square to a tilted surface and one cut vertically into it differ here; the
  // beam that cut it is vertical to a few degrees, so the midpoint of the two points, not
  // its foot on the surface along the surface's normal, is where its axis is.)
  const double zh = z0 - 0.5 * depth;
  const double centre = 0.5 * (c * (half_x[0] + half_x[1]) - 2.0 * s * zh);
  if (!(std::isfinite(centre) && std::isfinite(depth) && half_x[1] > half_x[0])) {
    return fail("no half-depth points either side of the groove's bottom");
  }
  g.ok = true;
  g.x_mm = centre;
  g.z_mm = (s * centre + z0) / c;  // the surface line above it
  g.depth_mm = depth;
  g.width_mm = 2.0 * (half_x[1] - half_x[0]);
  g.template_width_mm = q[3];
  g.template_depth_mm = q[2];
  g.tilt_rad = theta;
  g.points = static_cast<int>(levelled.size());
  g.rms_mm = std::sqrt(ss / static_cast<double>(levelled.size()));
  return g;
}

Result<AlphaChoice> ChooseAlpha(const std::vector<Profile>& sample, GrooveOptions o,
                                const std::vector<double>& candidates) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  if (candidates.empty()) return InvalidArgument("no alpha candidates");
  AlphaChoice choice;
  choice.candidates = candidates;
  // A candidate whose template fails on more than a tenth of the profiles another one fits is
  // not the grooves' shape; the others are compared over the same profiles, those that hold a
  // groove at each of them.
  std::vector<std::vector<Groove>> fits(candidates.size());
  std::vector<int> fitted(candidates.size(), 0);
  for (size_t k = 0; k < candidates.size(); ++k) {
    if (!(candidates[k] > 0)) return InvalidArgument("alpha candidates must be > 0");
    o.alpha_per_mm = candidates[k];
    for (const Profile& p : sample) {
      fits[k].push_back(FitGroove(p, o));
      fitted[k] += fits[k].back().ok ? 1 : 0;
    }
  }
  const int most = *std::max_element(fitted.begin(), fitted.end());
  std::vector<bool> eligible(candidates.size()), common(sample.size(), true);
  for (size_t k = 0; k < candidates.size(); ++k) {
    eligible[k] = most > 0 && fitted[k] >= 0.9 * most;
    if (!eligible[k]) continue;
    for (size_t i = 0; i < sample.size(); ++i) common[i] = common[i] && fits[k][i].ok;
  }
  double best = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < candidates.size(); ++k) {
    double ss = 0;
    long count = 0;
    for (size_t i = 0; i < sample.size() && eligible[k]; ++i) {
      if (!common[i]) continue;
      ss += fits[k][i].rms_mm * fits[k][i].rms_mm * fits[k][i].points;
      count += fits[k][i].points;
    }
    const double rms = count > 0 ? std::sqrt(ss / static_cast<double>(count)) : kNaN;
    choice.rms_mm.push_back(rms);
    if (rms < best) {
      best = rms;
      choice.alpha_per_mm = candidates[k];
    }
  }
  if (!std::isfinite(best)) {
    return FailedPrecondition("no profile of the sample holds a groove at any alpha candidate");
  }
  return choice;
}

}  // namespace insitu::inspect
