#include "mark_map.h"

#include <algorithm>
#include <cmath>

namespace insitu::sim {
namespace {

int64_t FloorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

float MarkMap::Cell(int64_t i, int64_t j) const {
  const auto it = tiles_.find(Key(FloorDiv(i, kTile), FloorDiv(j, kTile)));
  if (it == tiles_.end()) return 0.0f;
  const int64_t li = i - FloorDiv(i, kTile) * kTile, lj = j - FloorDiv(j, kTile) * kTile;
  return it->second[static_cast<size_t>(lj * kTile + li)];
}

float& MarkMap::CellRef(int64_t i, int64_t j) {
  std::vector<float>& tile = tiles_[Key(FloorDiv(i, kTile), FloorDiv(j, kTile))];
  if (tile.empty()) tile.assign(static_cast<size_t>(kTile) * kTile, 0.0f);
  const int64_t li = i - FloorDiv(i, kTile) * kTile, lj = j - FloorDiv(j, kTile) * kTile;
  return tile[static_cast<size_t>(lj * kTile + li)];
}

void MarkMap::AddCrater(double x, double y, double radius, double w, double delta_um) {
  if (!(radius > 0) || !(w > 0) || !(delta_um > 0)) return;
  const int64_t i0 = static_cast<int64_t>(std::floor((x - radius) / cell_mm_));
  const int64_t i1 = static_cast<int64_t>(std::ceil((x + radius) / cell_mm_));
  const int64_t j0 = static_cast<int64_t>(std::floor((y - radius) / cell_mm_));
  const int64_t j1 = static_cast<int64_t>(std::ceil((y + radius) / cell_mm_));
  const double scale = 2.0 * delta_um / (w * w), r2 = radius * radius;
  for (int64_t j = j0; j <= j1; ++j) {
    for (int64_t i = i0; i <= i1; ++i) {
      const double dx = i * cell_mm_ - x, dy = j * cell_mm_ - y;
      const double d = scale * (r2 - dx * dx - dy * dy);
      if (d > 0) CellRef(i, j) += static_cast<float>(d);
    }
  }
  Grow(i0, i1, j0, j1);
}

void MarkMap::AddFilmCrater(double x, double y, double w, double ln_film, double delta_film_um,
                            double film_um, double ln_sub, double delta_sub_um) {
  if (!(w > 0) || !(ln_film > 0 || ln_sub > 0)) return;
  // ln(F(r) / F_th) = ln(F0 / F_th) - 2 r^2 / w^2: the crater's radius where it reaches 0.
  const double ln_max = std::max(ln_film, ln_sub);
  const double radius = w * std::sqrt(0.5 * ln_max);
  const int64_t i0 = static_cast<int64_t>(std::floor((x - radius) / cell_mm_));
  const int64_t i1 = static_cast<int64_t>(std::ceil((x + radius) / cell_mm_));
  const int64_t j0 = static_cast<int64_t>(std::floor((y - radius) / cell_mm_));
  const int64_t j1 = static_cast<int64_t>(std::ceil((y + radius) / cell_mm_));
  const double k = 2.0 / (w * w);
  // Depths are stored as floats: the film's thickness compared as one too (0.3124 mm is no
  // float; as a double a cell would stop just short of it and never reach the metal).
  const float film = static_cast<float>(film_um);
  for (int64_t j = j0; j <= j1; ++j) {
    for (int64_t i = i0; i <= i1; ++i) {
      const double dx = i * cell_mm_ - x, dy = j * cell_mm_ - y;
      const double falloff = k * (dx * dx + dy * dy);
      const double removed = delta_film_um * (ln_film - falloff);
      const double sub = delta_sub_um * (ln_sub - falloff);
      if (removed <= 0 && sub <= 0) continue;
      float& d = CellRef(i, j);
      if (d < film) {
        if (removed > 0) d = std::min(static_cast<float>(d + removed), film);
      } else if (sub > 0) {
        d += static_cast<float>(sub);
      }
    }
  }
  Grow(i0, i1, j0, j1);
}

bool MarkMap::MarkedNear(double x, double y, double r) const {
  if (tiles_.empty()) return false;
  const int64_t t0x = FloorDiv(static_cast<int64_t>(std::floor((x - r) / cell_mm_)), kTile);
  const int64_t t1x = FloorDiv(static_cast<int64_t>(std::floor((x + r) / cell_mm_)), kTile);
  const int64_t t0y = FloorDiv(static_cast<int64_t>(std::floor((y - r) / cell_mm_)), kTile);
  const int64_t t1y = FloorDiv(static_cast<int64_t>(std::floor((y + r) / cell_mm_)), kTile);
  for (int64_t ty = t0y; ty <= t1y; ++ty) {
    for (int64_t tx = t0x; tx <= t1x; ++tx) {
      if (tiles_.count(Key(tx, ty)) != 0) return true;
    }
  }
  return false;
}

void MarkMap::Grow(int64_t i0, int64_t i1, int64_t j0, int64_t j1) {
  if (max_i_ < min_i_) {
    min_i_ = i0, max_i_ = i1, min_j_ = j0, max_j_ = j1;
  } else {
    min_i_ = std::min(min_i_, i0), max_i_ = std::max(max_i_, i1);
    min_j_ = std::min(min_j_, j0), max_j_ = std::max(max_j_, j1);
  }
}

double MarkMap::DepthUm(double x, double y) const {
  if (tiles_.empty()) return 0.0;
  const double fx = x / cell_mm_, fy = y / cell_mm_;
  const int64_t i = static_cast<int64_t>(std::floor(fx)), j = static_cast<int64_t>(std::floor(fy));
  if (i + 1 < min_i_ || i > max_i_ || j + 1 < min_j_ || j > max_j_) return 0.0;
  const double ax = fx - i, ay = fy - j;
  return (1 - ay) * ((1 - ax) * Cell(i, j) + ax * Cell(i + 1, j)) +
         ay * ((1 - ax) * Cell(i, j + 1) + ax * Cell(i + 1, j + 1));
}

bool MarkMap::Bounds(double* x0, double* y0, double* x1, double* y1) const {
  if (tiles_.empty()) return false;
  *x0 = min_i_ * cell_mm_, *x1 = max_i_ * cell_mm_;
  *y0 = min_j_ * cell_mm_, *y1 = max_j_ * cell_mm_;
  return true;
}

}  // namespace insitu::sim
