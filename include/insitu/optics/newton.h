// Inverting a smooth 2D map by Newton's method with a forward-difference Jacobian: the
// design-geometry solve of a command, and every "which command lands here" of the head models
// (the measured head, the fitted field models, a board driven linearly). Frames and units are
// the caller's.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>

namespace insitu::optics {

// Finds x with map(x) = target, starting from *x, to |map(x) - target| < tol; `step` is the
// finite-difference step. `map` returns a non-finite value where it has none. False when the
// map is non-finite, the Jacobian singular, or 40 steps do not converge (*x is then undefined).
template <typename Map>
bool InvertMap2d(const Map& map, const Eigen::Vector2d& target, double step, double tol,
                 Eigen::Vector2d* x) {
  for (int iter = 0; iter < 40; ++iter) {
    const Eigen::Vector2d p = map(*x);
    if (!p.allFinite()) return false;
    const Eigen::Vector2d r = p - target;
    if (r.norm() < tol) return true;
    Eigen::Matrix2d j;
    j.col(0) = (map(Eigen::Vector2d(*x + Eigen::Vector2d(step, 0))) - p) / step;
    j.col(1) = (map(Eigen::Vector2d(*x + Eigen::Vector2d(0, step))) - p) / step;
    const Eigen::Vector2d delta = j.fullPivLu().solve(r);
    if (!delta.allFinite()) return false;
    *x -= delta;
  }
  return false;
}

}  // namespace insitu::optics
