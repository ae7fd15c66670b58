// How deep the marking laser has ablated the surface, over the world xy plane:
// what the cameras see of the marks. Each pulse removes delta ln(F(r) / F_th)
// where its fluence exceeds the threshold (the logarithmic ablation law); for a
// Gaussian pulse of 1/e^2 radius w and crater radius R that is the paraboloid 2
// delta (R^2 - r^2) / w^2. Stored sparsely in square tiles of cells (4 um for
// marks on metal, coarser for wide grooves), so marks anywhere in the field cost
// memory only where they are.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace insitu::sim {

class MarkMap {
 public:
  static constexpr double kFineCellMm = 0.004;

  explicit MarkMap(double cell_mm = kFineCellMm) : cell_mm_(cell_mm) {}
  double cell_mm() const { return cell_mm_; }

  // Adds one crater at (x, y) mm: radius_mm (0: nothing), beam radius w_mm,
  // depth_um = delta.
  void AddCrater(double x_mm, double y_mm, double radius_mm, double w_mm, double delta_um);
  // One pulse into a film over a substrate: the film loses delta_film ln(F / F_th) where the
  // fluence passes its threshold, never past its thickness `film_um`; where the film is gone,
  // the substrate loses delta_sub ln(F / F_th,sub) where the fluence passes its own threshold.
  // ln_film, ln_sub: ln(F0 / F_th) at the pulse's peak fluence F0 (<= 0: nothing). A pulse that
  // finishes the film spends nothing on the metal; the metal starts with the next pulse there
  // (the film's last micrometres take the pulse's energy, a fraction of one pulse's depth).
  void AddFilmCrater(double x_mm, double y_mm, double w_mm, double ln_film, double delta_film_um,
                     double film_um, double ln_sub, double delta_sub_um);
  // True if anything is marked within r_mm of (x, y) (by whole tiles: may say true a tile
  // away).
  bool MarkedNear(double x_mm, double y_mm, double r_mm) const;
  // Ablated depth at (x, y), um, bilinear between cells.
  double DepthUm(double x_mm, double y_mm) const;
  bool empty() const { return tiles_.empty(); }
  // Bounding box of everything marked (mm); false if nothing is.
  bool Bounds(double* x0, double* y0, double* x1, double* y1) const;

 private:
  static constexpr int kTile = 64;  // cells per tile side
  static int64_t Key(int64_t tx, int64_t ty) { return (tx << 32) ^ (ty & 0xffffffff); }
  float Cell(int64_t i, int64_t j) const;
  float& CellRef(int64_t i, int64_t j);

  void Grow(int64_t i0, int64_t i1, int64_t j0, int64_t j1);

  double cell_mm_;
  std::unordered_map<int64_t, std::vector<float>> tiles_;
  int64_t min_i_ = 0, min_j_ = 0, max_i_ = -1, max_j_ = -1;
};

}  // namespace insitu::sim
