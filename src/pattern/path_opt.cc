#include "insitu/pattern/path_opt.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <utility>

#include <Eigen/Cholesky>

namespace insitu::pattern {

namespace {

using Vec = Eigen::Vector2d;

constexpr double kHalfPi = M_PI / 2.0;

double Cross(const Vec& a, const Vec& b) { return a.x() * b.y() - a.y() * b.x(); }

double SegmentDistance(const Vec& p, const Vec& a, const Vec& b) {
  const Vec ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (p - (a + t * ab)).norm();
}

PathEntity MakeLine(const Vec& a, const Vec& b) {
  PathEntity e;
  e.kind = PathEntity::Kind::kLine;
  e.control = {a, a + (b - a) / 3.0, a + 2.0 * (b - a) / 3.0, b};
  return e;
}

struct Cubic {
  Vec p0, p1, p2, p3;
  Vec At(double u) const {
    const double v = 1.0 - u;
    return v * v * v * p0 + 3.0 * v * v * u * p1 + 3.0 * v * u * u * p2 + u * u * u * p3;
  }
  Vec D1(double u) const {
    const double v = 1.0 - u;
    return 3.0 * (v * v * (p1 - p0) + 2.0 * v * u * (p2 - p1) + u * u * (p3 - p2));
  }
  Vec D2(double u) const {
    return 6.0 * ((1.0 - u) * (p2 - 2.0 * p1 + p0) + u * (p3 - 2.0 * p2 + p1));
  }
};

// seed 004 eq. (1)-(2): from each kept point the chord grows one point at a time while every
// point it skips stays within `eps` of it. The distance is to the segment, not to the infinite
// line of eq. (2): the same for points beside the chord, and a point that doubles back past an
// end is then not dropped. With it the chord is within `eps` of the skipped polyline both ways
// (the polyline runs from one end to the other, so it passes every point of the chord within
// `eps`). Returns the kept indices, lo and hi included.
std::vector<int> Thin(const std::vector<Vec>& p, int lo, int hi, double eps) {
  std::vector<int> keep{lo};
  int start = lo;
  while (start < hi) {
    int end = start + 1;
    while (end < hi) {
      const int next = end + 1;
      bool fits = true;
      for (int k = start + 1; k < next && fits; ++k) {
        fits = SegmentDistance(p[k], p[start], p[next]) <= eps;
      }
      if (!fits) break;
      end = next;
    }
    keep.push_back(end);
    start = end;
  }
  return keep;
}

// Curve-set tests at each interior thinned point (seed 004 eq. (3)).
struct Vertex {
  bool smooth = false;  // may lie inside a curve set
  double turn = 0.0;    // signed turn of the chord direction, rad
  double cos_turn = 1.0;
  bool significant = false;  // turns by more than noise: its sign counts for inflections
};

std::vector<Vertex> Vertices(const std::vector<Vec>& p, const std::vector<int>& kept,
                             const PathOptOptions& o) {
  const int m = static_cast<int>(kept.size());
  std::vector<Vertex> out(m);
  for (int k = 1; k + 1 < m; ++k) {
    const Vec a = p[kept[k]] - p[kept[k - 1]];
    const Vec b = p[kept[k + 1]] - p[kept[k]];
    const double la = a.norm(), lb = b.norm();
    Vertex& v = out[k];
    if (la <= 0 || lb <= 0) continue;
    v.cos_turn = a.dot(b) / (la * lb);
    v.turn = std::atan2(Cross(a, b), a.dot(b));
    // A chord more than line_length_ratio times its neighbour is a thinned straight line
    // (|P2P3| > 3 |P1P2|); tested both ways so a line entering a curve is cut as well.
    // The first and last chords are exempt from being the short one: where the sequence
    // starts and ends is no property of the curve.
    v.smooth = v.cos_turn > o.curve_cos_min && (k == 1 || lb <= o.line_length_ratio * la) &&
               (k + 2 == m || la <= o.line_length_ratio * lb);
    // The seed splits at third-order inflections where cos(alpha) stops exceeding
    // cos(beta), i.e. where the turn changes sign. Near an inflection the turns are tiny and
    // their sign is noise, so only a point lying more than eps_line / 2 off the chord of its
    // neighbours (twice the triangle area over the base) votes.
    const double base = (a + b).norm();
    v.significant = base > 0 && std::abs(Cross(a, b)) / base > 0.5 * o.eps_line;
  }
  return out;
}

// Unit tangent (towards increasing index) at p[at]: the derivative at p[at] of the least-squares
// cubic in chord length through p[at], over the points of [lo, hi] within `back` before and
// `ahead` after it (at least 4 a side where the range has them; a zero window uses no side).
Vec EstimateTangent(const std::vector<Vec>& p, const std::vector<double>& s, int at, int lo, int hi,
                    double back, double ahead) {
  std::vector<int> use;
  if (back > 0) {
    for (int k = at - 1; k >= lo && (s[at] - s[k] <= back || at - k <= 4); --k) use.push_back(k);
  }
  if (ahead > 0) {
    for (int k = at + 1; k <= hi && (s[k] - s[at] <= ahead || k - at <= 4); ++k) use.push_back(k);
  }
  Vec fallback = Vec::Zero();
  if (ahead > 0 && at < hi) fallback += (p[at + 1] - p[at]).normalized();
  if (back > 0 && at > lo) fallback += (p[at] - p[at - 1]).normalized();
  if (use.size() < 3) return fallback.normalized();
  const int degree = use.size() >= 6 ? 3 : 2;
  const double w = std::max(back, ahead) > 0 ? std::max(back, ahead) : 1.0;
  Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
  Eigen::Matrix<double, 3, 2> atb = Eigen::Matrix<double, 3, 2>::Zero();
  for (int k : use) {
    const double x = (s[k] - s[at]) / w;
    const Eigen::Vector3d phi(x, x * x, degree == 3 ? x * x * x : 0.0);
    ata += phi * phi.transpose();
    atb += phi * (p[k] - p[at]).transpose();
  }
  if (degree == 2) ata(2, 2) = 1.0;
  const Eigen::Matrix<double, 3, 2> coef = ata.ldlt().solve(atb);
  const Vec t = coef.row(0).transpose();
  if (!t.allFinite() || t.norm() == 0 || t.dot(fallback) <= 0) return fallback.normalized();
  return t.normalized();
}

class Fitter {
 public:
  Fitter(const std::vector<Vec>& p, const std::vector<double>& s, const PathOptOptions& o,
         std::vector<PathEntity>* out)
      : p_(p), s_(s), o_(o), out_(out) {}

  // Fits p[i0..i1] leaving p[i0] along t0 and reaching p[i1] along t1 (unit tangents);
  // [run_lo, run_hi] is the smooth run it belongs to (for tangents at new split points).
  void Fit(int i0, int i1, const Vec& t0, const Vec& t1, int run_lo, int run_hi, bool smooth_start,
           int depth) {
    const int n = i1 - i0 + 1;
    if (n < 4 || depth > kMaxDepth) return EmitLines(i0, i1, smooth_start, true);
    const Vec& a = p_[i0];
    const Vec& b = p_[i1];
    const Vec d = b - a;
    const double den = Cross(t0, t1);
    const double chord = d.norm();
    // Q, the intersection of the end tangents: a + lambda t0 = b - mu t1.
    const double lambda = std::abs(den) > 1e-12 ? Cross(d, t1) / den : -1.0;
    const double mu = std::abs(den) > 1e-12 ? Cross(t0, d) / den : -1.0;
    const bool triangle = lambda > 0 && mu > 0 && lambda < kMaxArm * chord && mu < kMaxArm * chord;
    if (!triangle) {
      // Parallel or diverging tangents: no triangle to search in. Nearly straight data is a
      // line; otherwise halve it and estimate the tangent where it is cut.
      if (Thin(p_, i0, i1, o_.eps_line).size() == 2) {
        return EmitLines(i0, i1, smooth_start, true);
      }
      return Split(i0, i1, MiddleIndex(i0, i1), t0, t1, run_lo, run_hi, smooth_start, depth);
    }
    const Vec q = a + lambda * t0;
    const double orient = Cross(d, q - a) >= 0 ? 1.0 : -1.0;
    // seed 004 section 1.3: bisection on t, P1 = P0 + t (Q - P0), P2 = P3 + t (Q - P3), until
    // the signed error sum (eq. 4) is below eps_s. At t = 0 the curve is the chord and the
    // points lie on Q's side (sum > 0); at t = 1 it bulges past them (sum < 0).
    double lo = 0.0, hi = 1.0, t = 0.5;
    Cubic c;
    for (int it = 0; it < kMaxBisections; ++it) {
      t = 0.5 * (lo + hi);
      c = {a, a + t * (q - a), b + t * (q - b), b};
      const double sum = Project(c, i0, i1, orient);
      if (std::abs(sum) < o_.eps_s || hi - lo < 1e-9) break;
      (sum > 0 ? lo : hi) = t;
    }
    const double e_max = std::max(MaxPointError(i0, i1), CurveToPolyline(c, i0, i1));
    if (e_max <= o_.e_per) {
      PathEntity e;
      e.kind = PathEntity::Kind::kCubic;
      e.control = {c.p0, c.p1, c.p2, c.p3};
      e.smooth_start = smooth_start;
      out_->push_back(e);
      return;
    }
    // Too far somewhere: cut where the curve crosses the data (a sign change of the signed
    // error; of the two points the one nearer the curve) closest to the middle, and refit.
    Split(i0, i1, CrossingIndex(i0, i1), t0, t1, run_lo, run_hi, smooth_start, depth);
  }

  // Thinned chords of p[i0..i1]: within eps_line of the data, so the error bound holds.
  // `smooth_start` for the first; `inside_curve`: they stand in for a piece of curve the
  // cubic fit gave up on (too short, or nearly straight), so the output may run across them.
  void EmitLines(int i0, int i1, bool smooth_start, bool inside_curve) {
    const std::vector<int> kept = Thin(p_, i0, i1, o_.eps_line);
    for (size_t k = 1; k < kept.size(); ++k) {
      out_->push_back(MakeLine(p_[kept[k - 1]], p_[kept[k]]));
      out_->back().smooth_start = k == 1 ? smooth_start : inside_curve;
    }
  }

 private:
  static constexpr int kMaxDepth = 40;
  static constexpr int kMaxBisections = 60;
  // Tangents meeting farther than this many chord lengths away count as parallel.
  static constexpr double kMaxArm = 1e4;
  static constexpr int kSamples = 32;  // coarse samples for the closest-point search

  void Split(int i0, int i1, int at, const Vec& t0, const Vec& t1, int run_lo, int run_hi,
             bool smooth_start, int depth) {
    if (at <= i0 || at >= i1) return EmitLines(i0, i1, smooth_start, true);
    // Tangent from a quarter of each half, both sides: the two halves meet tangentially.
    const Vec tm = EstimateTangent(p_, s_, at, run_lo, run_hi, 0.25 * (s_[at] - s_[i0]),
                                   0.25 * (s_[i1] - s_[at]));
    Fit(i0, at, t0, tm, run_lo, run_hi, smooth_start, depth + 1);
    Fit(at, i1, tm, t1, run_lo, run_hi, true, depth + 1);
  }

  int MiddleIndex(int i0, int i1) const {
    const double half = 0.5 * (s_[i0] + s_[i1]);
    const int at =
        static_cast<int>(std::lower_bound(s_.begin() + i0, s_.begin() + i1, half) - s_.begin());
    return std::clamp(at, i0 + 1, i1 - 1);
  }

  int CrossingIndex(int i0, int i1) const {
    const double half = 0.5 * (s_[i0] + s_[i1]);
    int best = -1;
    for (int k = i0 + 1; k + 1 < i1; ++k) {
      const int j = k - i0;
      if ((signed_[j] > 0) == (signed_[j + 1] > 0) && signed_[j] != 0) continue;
      const int at = std::abs(signed_[j]) <= std::abs(signed_[j + 1]) ? k : k + 1;
      if (at >= i1) continue;
      if (best < 0 || std::abs(s_[at] - half) < std::abs(s_[best] - half)) best = at;
    }
    // A crossing right at an end leaves a sliver that fits anything and cures nothing.
    const double len = s_[i1] - s_[i0];
    if (best < 0 || s_[best] - s_[i0] < 0.1 * len || s_[i1] - s_[best] < 0.1 * len) {
      return MiddleIndex(i0, i1);
    }
    return best;
  }

  // Closest point on `c` of every p[i0..i1] (parameters into u_, signed errors into signed_);
  // returns the signed error sum of eq. (4): positive for a point on Q's side of the curve.
  double Project(const Cubic& c, int i0, int i1, double orient) {
    const int n = i1 - i0 + 1;
    u_.assign(n, 0.0);
    signed_.assign(n, 0.0);
    Vec samples[kSamples + 1];
    for (int j = 0; j <= kSamples; ++j) samples[j] = c.At(static_cast<double>(j) / kSamples);
    const Vec chord = c.p3 - c.p0;
    const Vec c0 = c.p0, c1 = 3.0 * (c.p1 - c.p0), c2 = 3.0 * (c.p2 - 2.0 * c.p1 + c.p0);
    const Vec c3 = c.p3 - 3.0 * c.p2 + 3.0 * c.p1 - c.p0;
    double sum = 0.0;
    int best = 0;
    for (int k = 0; k < n; ++k) {
      const Vec& x = p_[i0 + k];
      // Nearest sample: the points run along the curve and lie far closer to it than its
      // radius of curvature, so the distance to the samples has one minimum; walk to it from
      // the previous point's.
      double best_d2 = (samples[best] - x).squaredNorm();
      for (int step : {1, -1}) {
        while (best + step >= 0 && best + step <= kSamples) {
          const double d2 = (samples[best + step] - x).squaredNorm();
          if (d2 >= best_d2) break;
          best_d2 = d2;
          best += step;
        }
      }
      // Safeguarded Newton on g(u) = C'(u) . (C(u) - x), bracketed by the neighbouring samples
      // (power basis: C(u) = c0 + u (c1 + u (c2 + u c3))).
      double lo = std::max(0.0, (best - 1.0) / kSamples);
      double hi = std::min(1.0, (best + 1.0) / kSamples);
      double u = static_cast<double>(best) / kSamples;
      for (int it = 0; it < 40; ++it) {
        const Vec r = c0 + u * (c1 + u * (c2 + u * c3)) - x;
        const Vec d1 = c1 + u * (2.0 * c2 + 3.0 * u * c3);
        const Vec d2 = 2.0 * c2 + 6.0 * u * c3;
        const double g = d1.dot(r);
        const double gp = d2.dot(r) + d1.squaredNorm();
        (g > 0 ? hi : lo) = u;
        double next = gp > 0 ? u - g / gp : 0.5 * (lo + hi);
        if (!(next >= lo && next <= hi)) next = 0.5 * (lo + hi);
        const bool done = std::abs(next - u) < 1e-12;
        u = next;
        if (done || hi - lo < 1e-12) break;
      }
      double e = (c.At(u) - x).norm();
      if (e * e > best_d2) {  // never worse than the nearest sample
        u = static_cast<double>(best) / kSamples;
        e = std::sqrt(best_d2);
      }
      Vec dir = c.D1(u);
      if (dir.squaredNorm() < 1e-24 * chord.squaredNorm()) dir = chord;
      const double side = Cross(dir, x - c.At(u));
      u_[k] = u;
      signed_[k] = (side * orient >= 0 ? e : -e);
      sum += signed_[k];
    }
    return sum;
  }

  double MaxPointError(int i0, int i1) const {
    double e = 0.0;
    for (int k = 0; k <= i1 - i0; ++k) e = std::max(e, std::abs(signed_[k]));
    return e;
  }

  // The other direction of the bound: the curve between the closest points of two successive
  // data points, sampled at its quarters, against the data segments there. (The consecutive
  // parameter intervals cover [0, 1], as the ends project to 0 and 1.)
  double CurveToPolyline(const Cubic& c, int i0, int i1) const {
    double e = 0.0;
    for (int k = i0; k < i1; ++k) {
      const double ua = u_[k - i0], ub = u_[k + 1 - i0];
      for (int j = 1; j <= 3; ++j) {
        const Vec x = c.At(ua + (ub - ua) * j / 4.0);
        double d = SegmentDistance(x, p_[k], p_[k + 1]);
        if (k > i0) d = std::min(d, SegmentDistance(x, p_[k - 1], p_[k]));
        if (k + 2 <= i1) d = std::min(d, SegmentDistance(x, p_[k + 1], p_[k + 2]));
        e = std::max(e, d);
      }
    }
    return e;
  }

  const std::vector<Vec>& p_;
  const std::vector<double>& s_;
  const PathOptOptions& o_;
  std::vector<PathEntity>* out_;
  std::vector<double> u_;       // closest-point parameters of the last Project
  std::vector<double> signed_;  // signed errors of the last Project
};

// A stretch of the sequence, p[i0..i1]: thinned chords (lines) or a curve piece, fitted as one
// or more cubics. `split_start`: the piece continues the previous one inside a smooth run.
struct Span {
  int i0 = 0, i1 = 0;
  bool curve = false;
  bool split_start = false;
  int run_lo = 0, run_hi = 0;  // the smooth run, for tangent estimates
};

// Steps 2 and 3 on an open sequence (a closed path arrives with its first point repeated).
std::vector<PathEntity> FitSequence(const std::vector<Vec>& p, const PathOptOptions& o) {
  const int n = static_cast<int>(p.size());
  std::vector<double> s(n, 0.0);
  for (int k = 1; k < n; ++k) s[k] = s[k - 1] + (p[k] - p[k - 1]).norm();
  const std::vector<int> kept = Thin(p, 0, n - 1, o.eps_line);
  const int m = static_cast<int>(kept.size());
  const std::vector<Vertex> v = Vertices(p, kept, o);

  std::vector<Span> spans;
  // Smooth runs: maximal stretches of thinned points whose interior points all pass the curve
  // tests; fewer than 4 points stay thinned chords.
  int run_a = 0;
  for (int k = 1; k < m; ++k) {
    if (k < m - 1 && v[k].smooth) continue;
    const int run_b = k;
    const int lo = kept[run_a], hi = kept[run_b];
    if (run_b - run_a + 1 < 4) {
      spans.push_back({lo, hi, false, false, lo, hi});
      run_a = k;
      continue;
    }
    // Inflections (pairs of thinned points turning opposite ways). Where the sign flips back
    // within fewer than 4 points it is noise (a chord straddling the inflection can lean
    // either way), not a curve set: that cut and the one before are dropped.
    std::vector<std::pair<int, int>> flips;
    int last = -1;
    for (int j = run_a + 1; j < run_b; ++j) {
      if (!v[j].significant) continue;
      if (last >= 0 && (v[j].turn > 0) != (v[last].turn > 0)) {
        const int before = flips.empty() ? run_a : flips.back().second;
        if (j - before + 1 >= 4 || flips.empty()) {
          if (last - run_a + 1 >= 3) flips.push_back({last, j});
        } else {
          flips.pop_back();
        }
      }
      last = j;
    }
    if (!flips.empty() && run_b - flips.back().first + 1 < 4) flips.pop_back();
    // Nodes of the run: its thinned points plus, for each inflection, the original point
    // half-way (by length) between the two that turn opposite ways, where the curvature
    // changes sign; the cut goes there.
    std::vector<int> node;
    std::vector<double> turn;
    for (int t = run_a; t <= run_b; ++t) {
      node.push_back(kept[t]);
      turn.push_back(t > run_a && t < run_b ? v[t].turn : 0.0);
    }
    std::vector<size_t> cuts{0};
    for (const auto& [first, second] : flips) {
      const int a = kept[first], b = kept[second];
      const double half = 0.5 * (s[a] + s[b]);
      int c = static_cast<int>(std::lower_bound(s.begin() + a, s.begin() + b, half) - s.begin());
      if (c > a && half - s[c - 1] < s[c] - half) --c;
      const auto at = std::lower_bound(node.begin(), node.end(), c);
      const size_t pos = static_cast<size_t>(at - node.begin());
      if (*at != c) {
        node.insert(at, c);
        turn.insert(turn.begin() + static_cast<std::ptrdiff_t>(pos), 0.0);
      }
      if (pos > cuts.back() && pos + 1 < node.size()) cuts.push_back(pos);
    }
    cuts.push_back(node.size() - 1);
    for (size_t c = 0; c + 1 < cuts.size(); ++c) {
      const size_t sub_b = cuts[c + 1];
      // Pieces turning their tangent by less than 90 degrees; a remainder of fewer than 4
      // points joins the piece before it.
      size_t st = cuts[c];
      while (st < sub_b) {
        double sum = 0.0;
        size_t e = st + 1;
        while (e < sub_b && std::abs(sum + turn[e]) < kHalfPi) sum += turn[e++];
        if (sub_b - e + 1 < 4) e = sub_b;
        if (e - st + 1 < 4) {
          spans.push_back({node[st], node[e], false, false, lo, hi});
        } else {
          const bool continues = !spans.empty() && spans.back().curve &&
                                 spans.back().i1 == node[st] && spans.back().run_lo == lo;
          spans.push_back({node[st], node[e], true, continues, lo, hi});
        }
        st = e;
      }
    }
    run_a = k;
  }

  std::vector<PathEntity> out;
  Fitter fitter(p, s, o, &out);
  Vec carried = Vec::Zero();  // the tangent at the start of the next piece, when it continues
  for (size_t i = 0; i < spans.size(); ++i) {
    const Span& sp = spans[i];
    if (!sp.curve) {
      fitter.EmitLines(sp.i0, sp.i1, false, false);
      continue;
    }
    const double len = s[sp.i1] - s[sp.i0];
    const Vec t0 =
        sp.split_start ? carried : EstimateTangent(p, s, sp.i0, sp.i0, sp.i1, 0.0, 0.25 * len);
    Vec t1;
    if (i + 1 < spans.size() && spans[i + 1].split_start) {
      const double next_len = s[spans[i + 1].i1] - s[sp.i1];
      t1 = EstimateTangent(p, s, sp.i1, sp.run_lo, sp.run_hi, 0.25 * len, 0.25 * next_len);
      carried = t1;
    } else {
      t1 = EstimateTangent(p, s, sp.i1, sp.i0, sp.i1, 0.25 * len, 0.0);
    }
    fitter.Fit(sp.i0, sp.i1, t0, t1, sp.run_lo, sp.run_hi, sp.split_start, 0);
  }
  return out;
}

// Uniform grid over the segments of a polyline for exact nearest-distance queries.
class SegmentGrid {
 public:
  // `lo`, `hi`: a box holding the polyline and every point that will be queried.
  SegmentGrid(const Polyline& line, const Vec& lo, const Vec& hi) : origin_(lo) {
    const std::vector<Vec>& pts = line.points;
    for (size_t k = 0; k + 1 < pts.size(); ++k) segs_.push_back({pts[k], pts[k + 1]});
    if (line.closed && pts.size() >= 3) segs_.push_back({pts.back(), pts.front()});
    if (segs_.empty() && !pts.empty()) segs_.push_back({pts[0], pts[0]});
    const Vec extent = (hi - lo).cwiseMax(Vec::Constant(1e-12));
    cell_ = std::max(extent.maxCoeff() / std::sqrt(static_cast<double>(segs_.size()) + 1.0), 1e-12);
    nx_ = static_cast<int>(extent.x() / cell_) + 1;
    ny_ = static_cast<int>(extent.y() / cell_) + 1;
    cells_.resize(static_cast<size_t>(nx_) * ny_);
    const double reach = 0.5 * std::sqrt(2.0) * cell_;
    for (int k = 0; k < static_cast<int>(segs_.size()); ++k) {
      const auto& [a, b] = segs_[k];
      const int x0 = CellX(std::min(a.x(), b.x())), x1 = CellX(std::max(a.x(), b.x()));
      const int y0 = CellY(std::min(a.y(), b.y())), y1 = CellY(std::max(a.y(), b.y()));
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          const Vec centre = origin_ + Vec(x + 0.5, y + 0.5) * cell_;
          if (SegmentDistance(centre, a, b) <= reach) cells_[Index(x, y)].push_back(k);
        }
      }
    }
  }

  // Distance from q to the polyline, and the index of a nearest segment.
  std::pair<double, int> Nearest(const Vec& q) const {
    const int cx = CellX(q.x()), cy = CellY(q.y());
    double best = std::numeric_limits<double>::infinity();
    int best_k = 0;
    const int rings = std::max(nx_, ny_);
    for (int r = 0; r <= rings; ++r) {
      for (int y = cy - r; y <= cy + r; ++y) {
        if (y < 0 || y >= ny_) continue;
        const bool edge_row = y == cy - r || y == cy + r;
        for (int x = cx - r; x <= cx + r; x += (edge_row || r == 0) ? 1 : 2 * r) {
          if (x < 0 || x >= nx_) continue;
          for (int k : cells_[Index(x, y)]) {
            const double d = SegmentTo(q, k);
            if (d < best) {
              best = d;
              best_k = k;
            }
          }
        }
      }
      // Segments not seen yet lie outside the searched block, at least r cells away.
      if (best <= r * cell_) break;
    }
    return {best, best_k};
  }

  double SegmentTo(const Vec& q, int k) const {
    return SegmentDistance(q, segs_[k].first, segs_[k].second);
  }

 private:
  int CellX(double x) const {
    return std::clamp(static_cast<int>((x - origin_.x()) / cell_), 0, nx_ - 1);
  }
  int CellY(double y) const {
    return std::clamp(static_cast<int>((y - origin_.y()) / cell_), 0, ny_ - 1);
  }
  size_t Index(int x, int y) const { return static_cast<size_t>(y) * nx_ + x; }

  Vec origin_;
  double cell_ = 1.0;
  int nx_ = 1, ny_ = 1;
  std::vector<std::pair<Vec, Vec>> segs_;
  std::vector<std::vector<int>> cells_;
};

// A run of entities joined without a corner (cubics, and lines evaluated as cubics) taken as
// one curve, parameter s in [0, count], cut into chords for output (seed 004 section 1.4).
class Chain {
 public:
  Chain(const PathEntity* first, size_t count, double delta, PathOptOptions::Placement placement)
      : delta_(delta), placement_(placement) {
    for (size_t k = 0; k < count; ++k) {
      const auto& c = first[k].control;
      cubics_.push_back({c[0], c[1], c[2], c[3]});
    }
  }

  // The mark points: the start, then the end of every chord but the last (the next entity's
  // start, or the path's end).
  std::vector<Vec> Marks() const {
    const double end = static_cast<double>(cubics_.size());
    std::vector<Vec> out{At(0.0)};
    Vec from = out.back();
    double s = 0.0, step = 0.125;
    while (s < end) {
      // The longest chord that holds: grow the step by doubling, then bisect (to 0.1%).
      double lo = s, hi = end;
      if (Holds(s, from, end)) {
        lo = end;
      } else {
        double h = step;
        while (s + h < end && Holds(s, from, s + h)) {
          lo = s + h;
          h *= 2.0;
        }
        if (s + h < end) hi = s + h;
        for (int it = 0; it < 60 && (lo == s || hi - lo > 1e-3 * (hi - s)); ++it) {
          const double mid = 0.5 * (lo + hi);
          (Holds(s, from, mid) ? lo : hi) = mid;
        }
        // Some progress whatever happens (a chord error far below the rounding of the
        // coordinates): at most kMaxChords chords a piece.
        lo = std::min(end, std::max(lo, s + 1.0 / kMaxChords));
        step = lo - s;
      }
      s = lo;
      if (s < end) {
        from = Vertex(s);
        out.push_back(from);
      }
    }
    return out;
  }

 private:
  // Checks at kInner points between a chord's ends. A deviation profile that is a parabola
  // over the chord (a short arc) is underestimated by at most h^2 of its top when sampled at
  // spacing h, so the samples are held to delta (1 - h^2); a little more for the arc's own
  // samples where they stand in for the arc (their chords sag by under h^2 of the arc's).
  static constexpr int kInner = 16;
  static constexpr double kH = 1.0 / (kInner + 1);
  static constexpr int kMaxChords = 1 << 14;

  Vec At(double s) const {
    const size_t k = std::min(static_cast<size_t>(s), cubics_.size() - 1);
    return cubics_[k].At(s - static_cast<double>(k));
  }

  // Where the mark for parameter s goes: on the curve, or for the band just inside delta on
  // the convex side (nowhere off the curve at the chain's end, a corner or a line's end).
  Vec Vertex(double s) const {
    const Vec p = At(s);
    if (placement_ != PathOptOptions::Placement::kToleranceBand ||
        s >= static_cast<double>(cubics_.size())) {
      return p;
    }
    const size_t k = std::min(static_cast<size_t>(s), cubics_.size() - 1);
    const double u = s - static_cast<double>(k);
    const Vec d1 = cubics_[k].D1(u), d2 = cubics_[k].D2(u);
    const double speed = d1.norm();
    if (speed == 0) return p;
    const double turn = Cross(d1, d2);
    if (turn == 0) return p;
    const Vec left(-d1.y() / speed, d1.x() / speed);
    return p - (turn > 0 ? 1.0 : -1.0) * kBandOffset * delta_ * left;
  }

  bool Holds(double a, const Vec& from, double b) const {
    const Vec to = Vertex(b);
    if (placement_ == PathOptOptions::Placement::kOnCurveSeedMidpoint &&
        (0.5 * (from + to) - At(0.5 * (a + b))).norm() > delta_) {
      return false;  // seed 004 eq. (5)
    }
    const double limit = delta_ * (1.0 - 2.0 * kH * kH);
    Vec arc[kInner + 2];
    for (int k = 0; k <= kInner + 1; ++k) arc[k] = At(a + (b - a) * k * kH);
    for (int k = 1; k <= kInner; ++k) {
      if (SegmentDistance(arc[k], from, to) > limit) return false;
    }
    if (placement_ != PathOptOptions::Placement::kToleranceBand) return true;
    // Off the curve the chord can also stray from the arc: the chord's points against the
    // arc's sample polyline, both in order along the curve (a missed nearer segment only
    // overestimates).
    int seg = 0;
    for (int k = 0; k <= kInner + 1; ++k) {
      const Vec x = from + (to - from) * (k * kH);
      double d = SegmentDistance(x, arc[seg], arc[seg + 1]);
      while (seg + 1 <= kInner) {
        const double next = SegmentDistance(x, arc[seg + 1], arc[seg + 2]);
        if (next > d) break;
        d = next;
        ++seg;
      }
      if (d > limit) return false;
    }
    return true;
  }

  // Band marks sit at this fraction of delta off the curve: the chord's middle may then lie
  // up to delta on the other side, and the vertex keeps a margin for the sampled checks.
  static constexpr double kBandOffset = 0.95;

  std::vector<Cubic> cubics_;
  double delta_;
  PathOptOptions::Placement placement_;
};

}  // namespace

Status PathOptOptions::Validate() const {
  const std::pair<const char*, double> positive[] = {{"eps_line", eps_line},
                                                     {"e_per", e_per},
                                                     {"eps_s", eps_s},
                                                     {"scale_mm_per_unit", scale_mm_per_unit},
                                                     {"chord_error_mm", chord_error_mm}};
  for (const auto& [name, value] : positive) {
    if (!std::isfinite(value) || !(value > 0)) {
      return InvalidArgument(std::string("path optimisation: ") + name +
                             " must be finite and > 0, got " + std::to_string(value));
    }
  }
  if (!(curve_cos_min > 0 && curve_cos_min < 1)) {
    return InvalidArgument("path optimisation: curve_cos_min must be in (0, 1), got " +
                           std::to_string(curve_cos_min));
  }
  if (!std::isfinite(line_length_ratio) || !(line_length_ratio > 1)) {
    return InvalidArgument("path optimisation: line_length_ratio must be finite and > 1, got " +
                           std::to_string(line_length_ratio));
  }
  return Status::Ok();
}

double PathOptOptions::FitErrorMm() const { return std::max(eps_line, e_per) * scale_mm_per_unit; }

PathOptOptions PathOptOptions::ForErrorBudget(double scale_mm_per_unit, double max_error_mm) {
  PathOptOptions o;
  o.scale_mm_per_unit = scale_mm_per_unit;
  const double fit = 0.25 * max_error_mm / scale_mm_per_unit;
  o.eps_line = o.e_per = o.eps_s = fit;
  o.chord_error_mm = 0.75 * max_error_mm;
  return o;
}

Eigen::Vector2d PathEntity::Evaluate(double u) const {
  return Cubic{control[0], control[1], control[2], control[3]}.At(u);
}

int OptimisedPath::ControlPoints() const {
  if (entities.empty()) return 0;
  int n = closed ? 0 : 1;
  for (const PathEntity& e : entities) n += e.kind == PathEntity::Kind::kCubic ? 3 : 1;
  return n;
}

Result<OptimisedPath> FitPath(const Polyline& polyline, const PathOptOptions& options) {
  INSITU_RETURN_IF_ERROR(options.Validate());
  std::vector<Vec> p;
  p.reserve(polyline.points.size() + 1);
  for (size_t k = 0; k < polyline.points.size(); ++k) {
    const Vec& x = polyline.points[k];
    if (!x.allFinite()) {
      return InvalidArgument("path optimisation: point " + std::to_string(k) + " is not finite");
    }
    if (p.empty() || x != p.back()) p.push_back(x);
  }
  if (polyline.closed) {
    while (p.size() > 1 && p.back() == p.front()) p.pop_back();
  }
  if (p.size() < 2) {
    return InvalidArgument("path optimisation: need at least 2 distinct points, got " +
                           std::to_string(p.size()));
  }
  OptimisedPath out;
  out.closed = polyline.closed;
  if (polyline.closed) {
    // Start a closed path at a corner where it has one, so that no smooth curve is cut at an
    // arbitrary first point: the sharpest non-smooth thinned point, the start if it is one.
    std::vector<Vec> cyc = p;
    cyc.push_back(p[0]);
    cyc.push_back(p[1]);
    const int n = static_cast<int>(p.size());
    const std::vector<int> kept = Thin(cyc, 0, static_cast<int>(cyc.size()) - 1, options.eps_line);
    const std::vector<Vertex> v = Vertices(cyc, kept, options);
    int start = 0;
    double sharpest = 2.0;
    bool start_is_corner = false;
    for (size_t k = 1; k + 1 < kept.size(); ++k) {
      if (v[k].smooth || kept[k] > n) continue;
      const int at = kept[k] % n;
      if (at == 0 && v[k].cos_turn <= options.curve_cos_min) start_is_corner = true;
      if (v[k].cos_turn < sharpest) {
        sharpest = v[k].cos_turn;
        start = at;
      }
    }
    if (!start_is_corner && start > 0) std::rotate(p.begin(), p.begin() + start, p.end());
    p.push_back(p.front());
  }
  out.entities = FitSequence(p, options);
  return out;
}

Polyline Interpolate(const OptimisedPath& path, const PathOptOptions& options) {
  Polyline out;
  out.closed = path.closed;
  const std::vector<PathEntity>& es = path.entities;
  if (es.empty() || !options.Validate().ok()) return out;
  const double scale = options.scale_mm_per_unit;
  const double delta = options.chord_error_mm / scale;  // input units
  for (size_t i = 0; i < es.size();) {
    size_t j = i + 1;
    while (j < es.size() && es[j].smooth_start) ++j;
    const Chain chain(es.data() + i, j - i, delta, options.placement);
    for (const Vec& x : chain.Marks()) out.points.push_back(scale * x);
    i = j;
  }
  if (!path.closed) out.points.push_back(scale * es.back().control[3]);
  return out;
}

double DirectedHausdorff(const Polyline& from, const Polyline& to, double tolerance) {
  if (from.points.empty() || to.points.empty()) return std::numeric_limits<double>::infinity();
  Vec lo = from.points[0], hi = from.points[0];
  for (const Polyline* l : {&from, &to}) {
    for (const Vec& x : l->points) {
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
  }
  const SegmentGrid grid(to, lo, hi);
  tolerance = std::max(tolerance, 1e-12 * (hi - lo).norm());  // terminates whatever is asked
  std::vector<std::pair<Vec, Vec>> segs;
  const std::vector<Vec>& pts = from.points;
  for (size_t k = 0; k + 1 < pts.size(); ++k) segs.push_back({pts[k], pts[k + 1]});
  if (from.closed && pts.size() >= 3) segs.push_back({pts.back(), pts.front()});
  double best = 0.0;
  for (const Vec& x : pts) best = std::max(best, grid.Nearest(x).first);
  // Two bounds on the largest distance over a piece [x0, x1] of a segment, from its ends:
  // the distance to one segment of `to` is convex along a line, so at most its larger end
  // value (taken for the nearest segment at either end); and the distance to `to` moves by
  // at most the distance moved, so at most (f0 + f1 + length) / 2. Pieces are halved until
  // neither bound can beat the best by more than `tolerance`.
  struct Piece {
    double x0, x1;
    std::pair<double, int> n0, n1;  // distance and nearest segment at each end
  };
  std::vector<Piece> stack;
  for (const auto& [a, b] : segs) {
    const double len = (b - a).norm();
    if (len == 0) continue;
    const Vec dir = (b - a) / len;
    stack.push_back({0.0, len, grid.Nearest(a), grid.Nearest(b)});
    while (!stack.empty()) {
      const Piece p = stack.back();
      stack.pop_back();
      const Vec p0 = a + p.x0 * dir, p1 = a + p.x1 * dir;
      double bound = 0.5 * (p.n0.first + p.n1.first + (p.x1 - p.x0));
      bound = std::min(bound, std::max(p.n0.first, grid.SegmentTo(p1, p.n0.second)));
      bound = std::min(bound, std::max(p.n1.first, grid.SegmentTo(p0, p.n1.second)));
      if (bound <= best + tolerance) continue;
      const double xm = 0.5 * (p.x0 + p.x1);
      const std::pair<double, int> nm = grid.Nearest(a + xm * dir);
      best = std::max(best, nm.first);
      stack.push_back({p.x0, xm, p.n0, nm});
      stack.push_back({xm, p.x1, nm, p.n1});
    }
  }
  return best + tolerance;
}

Result<OptimisedMarks> OptimisePolyline(const Polyline& polyline, const PathOptOptions& options) {
  INSITU_ASSIGN_OR_RETURN(OptimisedPath path, FitPath(polyline, options));
  OptimisedMarks out;
  out.marks = Interpolate(path, options);
  Polyline design = polyline;
  for (Vec& x : design.points) x *= options.scale_mm_per_unit;
  PathOptSummary& sum = out.summary;
  sum.input_points = static_cast<int>(polyline.points.size());
  sum.control_points = path.ControlPoints();
  sum.mark_points = static_cast<int>(out.marks.points.size());
  for (const PathEntity& e : path.entities) {
    (e.kind == PathEntity::Kind::kCubic ? sum.cubics : sum.lines) += 1;
  }
  sum.error_bound_mm = options.ErrorBoundMm();
  const double tolerance = 1e-3 * sum.error_bound_mm;
  sum.max_error_mm = std::max(DirectedHausdorff(design, out.marks, tolerance),
                              DirectedHausdorff(out.marks, design, tolerance));
  out.path = std::move(path);
  return out;
}

}  // namespace insitu::pattern
