// A dense, unevenly sampled closed outline comparable to seed 004 Fig. 2, for the path
// optimisation test and benchmark: the outline of a "2" glyph about 210 x 310 "pixels" (the
// seed's unit; 1 px = 0.06 mm at 36x, 0.12 mm at 72x), made of 11 curved pieces (arcs of radius
// 10 to 140 px and cubics, two of them S-shaped) and 5 straight edges, with 5 sharp corners.
//
// Sampling, as a CAD export of a curve would be: along each curve the spacing is uneven
// (uniform in 0.3 .. 1.5 px) but never so wide that a chord departs from the curve by more than
// kFlatteningPx (0.002 px: 0.12 um at 36x); the straight edges hold the rest of the 1181 points
// at random positions. Every point then gets a uniform jitter of +-0.001 px. All randomness comes
// from a fixed-seed mt19937_64 mapped to doubles here (not std:: distributions, whose output
// differs between standard libraries), so the points are the same everywhere.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "insitu/pattern/vector.h"

namespace insitu::pattern::testing {

inline constexpr int kDenseOutlinePoints = 1181;
inline constexpr double kFlatteningPx = 0.002;
inline constexpr double kJitterPx = 0.001;

namespace dense_outline_detail {

using Vec = Eigen::Vector2d;

struct Piece {
  enum class Kind { kLine, kArc, kCubic } kind = Kind::kLine;
  // Line: a to b. Cubic: a, b, c, d. Arc: centre, radius, start angle and sweep (rad).
  Vec a = Vec::Zero(), b = Vec::Zero(), c = Vec::Zero(), d = Vec::Zero();
  Vec centre = Vec::Zero();
  double radius = 0, start = 0, sweep = 0;

  Vec At(double u) const {
    switch (kind) {
      case Kind::kLine:
        return a + u * (b - a);
      case Kind::kArc: {
        const double t = start + u * sweep;
        return centre + radius * Vec(std::cos(t), std::sin(t));
      }
      case Kind::kCubic: {
        const double v = 1 - u;
        return v * v * v * a + 3 * v * v * u * b + 3 * v * u * u * c + u * u * u * d;
      }
    }
    return a;
  }
};

// Turtle: position and heading; pieces join tangentially unless Turn() makes a corner.
class Turtle {
 public:
  Turtle(Vec start, double heading_deg) : pos_(start), heading_(Rad(heading_deg)) {}

  void Line(double length) {
    Piece p;
    p.a = pos_;
    pos_ += length * Dir(heading_);
    p.b = pos_;
    pieces_.push_back(p);
  }
  // Positive sweep turns left (counter-clockwise).
  void Arc(double radius, double sweep_deg) {
    const double sweep = Rad(sweep_deg);
    const double side = sweep > 0 ? 1.0 : -1.0;
    Piece p;
    p.kind = Piece::Kind::kArc;
    p.centre = pos_ + side * radius * Dir(heading_ + M_PI / 2);
    p.radius = radius;
    p.start = heading_ - side * M_PI / 2;
    p.sweep = sweep;
    heading_ += sweep;
    pos_ = p.At(1.0);
    pieces_.push_back(p);
  }
  // A cubic leaving along the current heading, arriving at `end` along `end_heading_deg`,
  // with control arms of the given lengths.
  void CubicTo(Vec end, double end_heading_deg, double arm0, double arm1) {
    Piece p;
    p.kind = Piece::Kind::kCubic;
    p.a = pos_;
    p.b = pos_ + arm0 * Dir(heading_);
    heading_ = Rad(end_heading_deg);
    p.c = end - arm1 * Dir(heading_);
    p.d = end;
    pos_ = end;
    pieces_.push_back(p);
  }
  void Turn(double deg) { heading_ += Rad(deg); }

  const std::vector<Piece>& pieces() const { return pieces_; }

 private:
  static double Rad(double deg) { return deg * M_PI / 180.0; }
  static Vec Dir(double a) { return Vec(std::cos(a), std::sin(a)); }
  Vec pos_;
  double heading_;
  std::vector<Piece> pieces_;
};

inline std::vector<Piece> GlyphPieces() {
  Turtle t({0, 0}, 0);
  t.Line(210);  // base
  t.Turn(90);
  t.Line(50);
  t.Turn(90);
  t.Line(100);
  t.Turn(-118);
  t.CubicTo({191.6, 160.0}, 60, 45, 45);  // lower edge of the diagonal stroke, S-shaped
  t.Arc(100, 60);                         // outer bowl
  t.CubicTo({105, 310}, 180, 35, 55);
  t.Arc(70, 60);
  t.Arc(140, 25);
  t.Arc(10, 95);  // rounded corner of the terminal
  t.Line(40);     // terminal
  t.Turn(90);
  t.Arc(45, -90);  // inner bowl
  t.CubicTo({175, 215}, -80, 25, 20);
  t.Arc(110, -45);
  t.CubicTo({5.86, 54.14}, 225, 70, 60);  // upper edge of the diagonal stroke, S-shaped
  t.Arc(20, 45);
  t.Line(40);  // back to the start
  return t.pieces();
}

// Uniform double in [0, 1) from 53 bits of mt19937_64.
inline double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1p-53; }

}  // namespace dense_outline_detail

// The 1181 points (closed; the first point is not repeated), pixels.
inline Polyline DenseGlyphOutline() {
  using namespace dense_outline_detail;
  const std::vector<Piece> pieces = GlyphPieces();
  std::mt19937_64 rng(4);
  std::vector<std::vector<Vec>> interior(pieces.size());
  int total = 0;
  double line_length = 0;
  for (size_t k = 0; k < pieces.size(); ++k) {
    total += 1;  // the piece's start point
    const Piece& p = pieces[k];
    if (p.kind == Piece::Kind::kLine) {
      line_length += (p.b - p.a).norm();
      continue;
    }
    // Arc length and curvature tables, then uneven steps along the arc length.
    constexpr int kTable = 4000;
    std::vector<double> s(kTable + 1, 0.0), kappa(kTable + 1, 0.0);
    std::vector<Vec> x(kTable + 1);
    for (int i = 0; i <= kTable; ++i) x[i] = p.At(static_cast<double>(i) / kTable);
    for (int i = 1; i <= kTable; ++i) s[i] = s[i - 1] + (x[i] - x[i - 1]).norm();
    for (int i = 1; i < kTable; ++i) {
      const Vec d1 = x[i] - x[i - 1], d2 = x[i + 1] - x[i];
      kappa[i] = std::abs(d1.x() * d2.y() - d1.y() * d2.x()) /
                 (d1.norm() * d2.norm() * 0.5 * (d1 + d2).norm());
    }
    kappa[0] = kappa[1];
    kappa[kTable] = kappa[kTable - 1];
    double at = 0;
    int i = 0;
    while (true) {
      // Largest curvature over the next 2 px bounds the chord's departure from the curve.
      double kmax = 0;
      for (int j = i; j <= kTable && s[j] <= at + 2.0; ++j) kmax = std::max(kmax, kappa[j]);
      const double cap = kmax > 0 ? std::sqrt(8.0 * kFlatteningPx / kmax) : 1e9;
      const double step = std::min(0.3 + 1.2 * Uniform(rng), cap);
      if (at + step >= s[kTable] - 0.05) break;
      at += step;
      while (i < kTable && s[i + 1] < at) ++i;
      const double f = (at - s[i]) / (s[i + 1] - s[i]);
      interior[k].push_back(p.At((i + f) / kTable));
      ++total;
    }
  }
  // The straight edges share the remaining points by length (largest remainder), placed at
  // sorted random positions.
  const int spare = kDenseOutlinePoints - total;
  std::vector<int> counts(pieces.size(), 0);
  std::vector<std::pair<double, size_t>> remainders;
  int given = 0;
  for (size_t k = 0; k < pieces.size(); ++k) {
    if (pieces[k].kind != Piece::Kind::kLine) continue;
    const double share = spare * (pieces[k].b - pieces[k].a).norm() / line_length;
    counts[k] = static_cast<int>(share);
    given += counts[k];
    remainders.push_back({share - counts[k], k});
  }
  std::sort(remainders.rbegin(), remainders.rend());
  for (int r = 0; r < spare - given; ++r) ++counts[remainders[r].second];
  for (size_t k = 0; k < pieces.size(); ++k) {
    if (counts[k] <= 0) continue;
    std::vector<double> u(counts[k]);
    for (double& x : u) x = 0.01 + 0.98 * Uniform(rng);
    std::sort(u.begin(), u.end());
    for (double x : u) interior[k].push_back(pieces[k].At(x));
  }
  Polyline out;
  out.closed = true;
  for (size_t k = 0; k < pieces.size(); ++k) {
    out.points.push_back(pieces[k].At(0.0));
    for (const Vec& x : interior[k]) out.points.push_back(x);
  }
  for (Vec& x : out.points) {
    x += kJitterPx * Vec(2 * Uniform(rng) - 1, 2 * Uniform(rng) - 1);
  }
  return out;
}

}  // namespace insitu::pattern::testing
