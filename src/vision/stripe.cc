// Laser-stripe centre extraction (seed 000 section 2.3, eq. 7). See stripe.h for the contract.
//
// Why a hand-written filter and not cv::medianBlur: the extractor has to keep up with the camera
// (budget: 4x a memcpy of the frame, see bench/stripe_bench.cc). Measured with stripe_bench on
// the 2 shared cores of the development machine (2592 x 1944 8-bit frame, several runs): memcpy
// of the frame 0.10-0.14 ms; cv::medianBlur 3x3 alone 0.93 ms, i.e. 7-10x the memcpy and over
// budget before a single centre is found; the straightforward OpenCV per-column version
// (medianBlur, then minMaxLoc / threshold / moments on img.col(u)) 38-40 ms; this file
// 0.20-0.23 ms, i.e. 1.5-2.2x the memcpy and 150-190x faster than that baseline. The stripe
// covers a few percent of the frame, so the exact 3x3 median is only computed there.
//
// Design (kColumns; kRows transposes the frame first, which is simple and exactly equivalent):
//
// Pass 1 streams the rows once (each row comes from memory once, its neighbours from L1) and
// computes the vertical 3-tap median v(u, r) = median(p(u, r-1), p(u, r), p(u, r+1)) of every
// pixel with branch-free min/max loops over the row that the compiler vectorizes (an AVX2 clone
// via target_clones measured 20% faster than the SSE2 default; an AVX-512 clone no faster). It
// keeps, per column and per block of 8 rows (16 or more in frames over 2048 rows), the maximum of
// v (and per superblock of 8 blocks), the column's maximum of v and the first block reaching it:
// where the stripe is.
//
// These maxima bound the exact filter: the 3x3 median m(u, r) is at most the largest of the
// three vertical medians v(u-1..u+1, r) (each column has two of its three values <= its median,
// so six of the nine values are <= the largest of them). So a block whose maximum of v over
// columns u-1..u+1 is <= K cannot hold a pixel of column u with m > K, and a column whose bound
// is below min_peak holds no stripe; neither needs filtering.
//
// Between the passes, a ridge table from the same block maxima (RidgeBody, vectorized): per
// column, the block standing highest above both blocks 16 rows away, and whether there are
// others. The stripe is sought there, not at the brightest block: a white label, a lit face or a
// board is bright but no ridge.
//
// Pass 2 works on groups of kGroupCols columns whose stripes lie in nearby blocks: it computes the
// exact 3x3 median m only in the band of blocks around the stripes and reach_ rows beyond
// (vectorized across the group's columns, sorted-triple method) with the band's peaks that pass
// the first test (PeakFlags), then per column (Decide): the candidate at the ridge, every other
// peak in the band, at the column's other ridges and near those, each evaluated once
// (Evaluate: valleys, local background windows, K above them, the run, the centroid of g - K,
// the shape tests) and weighed (Verdict: one stripe, two, or none). Rows outside the tile are
// filtered exactly where they are needed (Outside). Then per frame: the width test against the
// frame's stripe and the continuity test (WidthTest, IsolationTest). With a window, pass 1
// reads only the rows some scan line's window holds (WindowedBlocks).
//
// The scan line's background for the first test of an empty column (min_contrast) is the
// median of the raw profile sampled on kBackgroundSamples evenly spaced rows (an exact median of
// the sample, computed for all columns at once by a bitwise radix select).
#include "insitu/vision/stripe.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace insitu::vision {
namespace {

// Rows per block of pass 1 (at least; doubled until the block index fits the sample type).
// Small blocks keep the band of exact filtering (3 blocks at least) and the far-peak scans short;
// 8 rows measured faster than 16 (band of 24 instead of 48 rows) and keeps the block table
// (H / 8 x W) inside L2.
constexpr int kMinBlockRows = 8;
// Columns handled together in pass 2 (two AVX2 vectors of uint8).
constexpr int kGroupCols = 64;
// A group is split when its columns' stripe blocks spread over more than this many blocks
// (steep or broken stripes), so the exactly filtered band stays short.
constexpr int kMaxBlockSpread = 2;
// Rows a ridge looks to either side (R(b) of RidgeBody: d blocks of at least this many rows): a
// stripe of up to ~13 px at half its peak has fallen to a few percent there, while a lit surface
// or a white label wider than twice this shows no ridge inside.
constexpr int kRidgeRows = 16;
// The symmetry test: a valid centre lies within this fraction of the run's width at K, plus a
// slack, of the run's mid-point. Speckle (contrast 0.2, grains of ~2-3 px) moves a stripe's
// centroid against its half-level crossings by up to ~0.1 of the width; a shoulder of a third of
// the peak merged into the run moves it by a quarter.
constexpr double kMaxAsymmetry = 0.15;
// The centroid's window, in beam sigmas either side of the stripe: a Gaussian's weight beyond 3
// sigma is 0.3 % of it.
constexpr double kWindowSigmas = 3.0;
// The background's step across that window, as a fraction of the stripe's contrast, beyond which
// the window's centroid is not used: a line through a step D leaves +-D/2 at the window's ends,
// antisymmetric about the centre, and moves the centre by ~0.9 D / contrast pixels for a
// sigma of 1.5 px (the window's first moment of that error over the stripe's sum, 3.8 sigma
// contrast): 0.1 keeps it under ~0.1 px, the speckle's scatter.
constexpr double kMaxBackgroundStep = 0.1;
constexpr double kAsymmetrySlackPx = 0.35;
// The width test: at most this many times the frame's stripe width at K, plus a slack (a narrow
// stripe's width is quantized by the pixels), and the least sample of valid columns that gives
// the frame's width.
constexpr double kMaxWidthRatio = 1.75;
constexpr double kWidthSlackPx = 1.5;
constexpr size_t kMinWidthSample = 16;
// The least width at K of a stripe: one pixel alone above K (a hot pixel with no median
// filter) crosses K half a pixel either side, width 1.0; a beam blurred to sigma >= 0.5 px (any
// lens's diffraction and the pixel box) is wider than 1.16.
constexpr double kMinWidthPx = 1.1;
// The continuity test: a centre this far (pixels) from the agreeing centres of the kIsolatedReach
// scan lines on each side is isolated. Speckle moves centres by ~0.2 px rms, a surface's
// slope by a pixel per scan line at the steepest a stripe stays valid; 3 px is neither.
constexpr float kIsolatedPx = 3.0f;
constexpr int kIsolatedReach = 4;
// Valid candidates weighed per scan line, at most (a lit texture can hold many peaks).
constexpr size_t kMaxCandidates = 16;
// Rows of a column's exact profile computed at once outside its band (Outside).
constexpr int kOutsideRows = 16;
// Peaks of one column evaluated at most (see Decide).
constexpr size_t kMaxPeaks = 64;
// Ridges of a column whose blocks pass 1 lists (more: Decide looks along the column).
constexpr int kRidgeSlots = 4;
// Rows sampled per column for the background median (odd: the median is one sample).
constexpr int kBackgroundSamples = 31;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define INSITU_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define INSITU_VECTOR_CLONES
#endif
#define INSITU_INLINE [[gnu::always_inline]] inline
#define INSITU_LAMBDA_INLINE __attribute__((always_inline))

template <typename T>
INSITU_INLINE T Min(T a, T b) {
  return b < a ? b : a;
}
template <typename T>
INSITU_INLINE T Max(T a, T b) {
  return a < b ? b : a;
}
// Median of three with four min/max and no branch.
template <typename T>
INSITU_INLINE T Med3(T a, T b, T c) {
  return Max(Min(a, b), Min(Max(a, b), c));
}

// Typed view of the frame.
template <typename T>
struct Plane {
  const uint8_t* base = nullptr;
  size_t stride = 0;
  int width = 0;
  int height = 0;

  const T* row(int v) const { return reinterpret_cast<const T*>(base + v * stride); }
  const T* row_clamped(int v) const { return row(std::clamp(v, 0, height - 1)); }
};

// One stripe candidate of a scan line, as Evaluate finds it.
struct Candidate {
  StripeStatus status = StripeStatus::kNone;
  int rp = 0;             // the local maximum of the filtered profile
  int gmax = 0;           // its value
  int rs = 0, re = -1;    // the run above K (rows)
  double base = 0.0;      // the local background under the peak
  double contrast = 0.0;  // gmax - base
  double center = 0.0;    // eq. (7) over the run above K (Evaluate), then the window (Refine)
  double sigma = 0.0;     // the centre's 1-sigma from the local noise
  double width = 0.0;     // the run's width at K, interpolated between pixels
  // For Refine: the local noise's variance, the background windows' length, and the
  // background line at the run's ends.
  double noise2 = 0.0;
  double run_weight = 0.0;  // sum of g - K over the run
  int bg_len = 0;
  double bg_rs = 0.0, bg_re = 0.0;
};

// Scratch buffers for one sample type; sized on the first frame and reused.
template <typename T>
struct Work {
  std::vector<T> acc;         // W: pass 1 running block maximum of v (generic blocks)
  std::vector<T> blocks;      // nb x W: block maximum of v
  std::vector<T> colmax;      // W: maximum of v over the column
  std::vector<T> argblock;    // W: first block holding colmax
  std::vector<T> upper;       // W: colmax over u-1..u+1, bounds the exact gmax
  std::vector<T> samples;     // kBackgroundSamples x W raw rows
  std::vector<T> background;  // W
  std::vector<T> probe;       // W, radix select scratch
  std::vector<T> count;       // W, radix select scratch
  std::vector<T> ridge_prev, ridge_cur, ridge_next;  // W each: R of three consecutive blocks
  std::vector<T> ridge, ridge_block;                 // W: the largest ridge and its block
  std::vector<uint8_t> ridge_count;  // W: ridges reaching the floor, up to kRidgeSlots + 1
  std::vector<T> ridge_slots;        // kRidgeSlots x W: their blocks, down the column
  // Pass 2, one group.
  std::vector<T> pad, lo, mid, hi, tile;
  std::vector<uint8_t> peak_flag;   // per tile pixel: a peak passing the pre-test (PeakFlags)
  std::vector<uint8_t> peak_count;  // per group column: its flags
  // One column's exact values outside its band, computed once each (Decide's profile).
  std::vector<T> exact;
  std::vector<uint32_t> exact_stamp;  // == the column's stamp where `exact` holds its value
  uint32_t stamp = 0;
  std::vector<uint8_t> candidate;
  std::vector<T> seed_block;  // per group column: the block its stripe is sought in
  std::vector<float> widths;  // W: valid columns' widths at K, for the frame's width test
  std::vector<float> sorted_widths;  // WidthTest's
  std::vector<uint8_t> refuse;       // IsolationTest's: scan lines to refuse this round
  std::vector<float> evidence;  // W: where each scan line sees the stripe (valid or clipped)
  std::vector<int> offband;     // one column's valid peaks found outside its band
  std::vector<int> seen;        // one column's peaks evaluated
  std::vector<Candidate> found, valid;  // one column's candidates (Decide, Verdict)
  std::vector<T> transposed;
};

// ---------------------------------------------------------------------------------------------
// Pass 1 kernels.

// acc = max(acc, v(rows r..r+3)) where a..f are rows r-1..r+4 (clamped at the image border).
// The pairs (b, c) and (d, e) are shared by two medians each: 4 min/max per output row.
template <typename T, bool kMedian, bool kInit>
INSITU_INLINE void AccumulateRows4(const T* __restrict a, const T* __restrict b,
                                   const T* __restrict c, const T* __restrict d,
                                   const T* __restrict e, const T* __restrict f, T* __restrict acc,
                                   int n) {
  for (int u = 0; u < n; ++u) {
    T m;
    if constexpr (kMedian) {
      const T lo_bc = Min(b[u], c[u]);
      const T hi_bc = Max(b[u], c[u]);
      const T lo_de = Min(d[u], e[u]);
      const T hi_de = Max(d[u], e[u]);
      const T m0 = Max(lo_bc, Min(hi_bc, a[u]));  // median(a, b, c)
      const T m1 = Max(lo_bc, Min(hi_bc, d[u]));  // median(b, c, d)
      const T m2 = Max(lo_de, Min(hi_de, c[u]));  // median(c, d, e)
      const T m3 = Max(lo_de, Min(hi_de, f[u]));  // median(d, e, f)
      m = Max(Max(m0, m1), Max(m2, m3));
    } else {
      m = Max(Max(b[u], c[u]), Max(d[u], e[u]));
    }
    acc[u] = kInit ? m : Max(acc[u], m);
  }
}

template <typename T, bool kMedian, bool kInit>
INSITU_INLINE void AccumulateRow1(const T* __restrict a, const T* __restrict b,
                                  const T* __restrict c, T* __restrict acc, int n) {
  for (int u = 0; u < n; ++u) {
    const T m = kMedian ? Med3(a[u], b[u], c[u]) : b[u];
    acc[u] = kInit ? m : Max(acc[u], m);
  }
}

// A whole block of 8 rows in one sweep (rows[0..9] are rows r0-1..r0+8, clamped): the 8
// vertical medians share their middle pairs, their maximum goes straight to the block table,
// the superblock maximum and the column maximum. Fusing the block's bookkeeping into the row
// loop measured ~20% faster for pass 1 than accumulating 4 rows at a time and sweeping the
// block's columns afterwards.
template <typename T, bool kMedian>
INSITU_INLINE void Block8(const T* const* rows, T* __restrict out, T* __restrict colmax,
                          T* __restrict argblock, T block_id, int n) {
  const T* __restrict x0 = rows[0];
  const T* __restrict x1 = rows[1];
  const T* __restrict x2 = rows[2];
  const T* __restrict x3 = rows[3];
  const T* __restrict x4 = rows[4];
  const T* __restrict x5 = rows[5];
  const T* __restrict x6 = rows[6];
  const T* __restrict x7 = rows[7];
  const T* __restrict x8 = rows[8];
  const T* __restrict x9 = rows[9];
  for (int u = 0; u < n; ++u) {
    T m;
    if constexpr (kMedian) {
      const T lo12 = Min(x1[u], x2[u]), hi12 = Max(x1[u], x2[u]);
      const T lo34 = Min(x3[u], x4[u]), hi34 = Max(x3[u], x4[u]);
      const T lo56 = Min(x5[u], x6[u]), hi56 = Max(x5[u], x6[u]);
      const T lo78 = Min(x7[u], x8[u]), hi78 = Max(x7[u], x8[u]);
      const T m0 = Max(lo12, Min(hi12, x0[u]));  // median(x0, x1, x2)
      const T m1 = Max(lo12, Min(hi12, x3[u]));  // median(x1, x2, x3)
      const T m2 = Max(lo34, Min(hi34, x2[u]));
      const T m3 = Max(lo34, Min(hi34, x5[u]));
      const T m4 = Max(lo56, Min(hi56, x4[u]));
      const T m5 = Max(lo56, Min(hi56, x7[u]));
      const T m6 = Max(lo78, Min(hi78, x6[u]));
      const T m7 = Max(lo78, Min(hi78, x9[u]));
      m = Max(Max(Max(m0, m1), Max(m2, m3)), Max(Max(m4, m5), Max(m6, m7)));
    } else {
      m = Max(Max(Max(x1[u], x2[u]), Max(x3[u], x4[u])), Max(Max(x5[u], x6[u]), Max(x7[u], x8[u])));
    }
    out[u] = m;
    const bool gt = m > colmax[u];
    colmax[u] = gt ? m : colmax[u];
    argblock[u] = gt ? block_id : argblock[u];
  }
}

template <typename T, bool kMedian>
INSITU_INLINE void Pass1Body(const Plane<T>& p, Work<T>& w, int block_rows, int sample_step,
                             int num_samples, int first, int last) {
  const int width = p.width;
  const int height = p.height;
  T* __restrict acc = w.acc.data();
  T* __restrict colmax = w.colmax.data();
  T* __restrict argblock = w.argblock.data();
  std::fill_n(colmax, width, T{0});
  std::fill_n(argblock, width, T{0});
  // Sample k is row sample_step / 2 + k sample_step, over the whole frame.
  int sample = 0;
  int next_sample = sample_step / 2;
  while (sample < num_samples && next_sample < first * block_rows) {
    ++sample;
    next_sample += sample_step;
  }
  for (int b = first; b <= last; ++b) {
    const int r0 = b * block_rows;
    const int r1 = std::min(height, r0 + block_rows);
    const T block_id = static_cast<T>(b);  // fits: see ColumnExtractor()
    T* __restrict out = w.blocks.data() + static_cast<size_t>(b) * width;
    if (r1 - r0 == 8) {
      const T* rows[10];
      for (int i = 0; i < 10; ++i) rows[i] = p.row_clamped(r0 - 1 + i);
      Block8<T, kMedian>(rows, out, colmax, argblock, block_id, width);
    } else {
      // Taller blocks (tall frames) and the last, partial block: 4 rows at a time into acc.
      int r = r0;
      for (; r + 3 < r1; r += 4) {
        const T* ra = p.row_clamped(r - 1);
        const T* rb = p.row(r);
        const T* rc = p.row(r + 1);
        const T* rd = p.row(r + 2);
        const T* re = p.row(r + 3);
        const T* rf = p.row_clamped(r + 4);
        if (r == r0) {
          AccumulateRows4<T, kMedian, true>(ra, rb, rc, rd, re, rf, acc, width);
        } else {
          AccumulateRows4<T, kMedian, false>(ra, rb, rc, rd, re, rf, acc, width);
        }
      }
      for (; r < r1; ++r) {
        if (r == r0) {
          AccumulateRow1<T, kMedian, true>(p.row_clamped(r - 1), p.row(r), p.row_clamped(r + 1),
                                           acc, width);
        } else {
          AccumulateRow1<T, kMedian, false>(p.row_clamped(r - 1), p.row(r), p.row_clamped(r + 1),
                                            acc, width);
        }
      }
      for (int u = 0; u < width; ++u) {
        const T m = acc[u];
        out[u] = m;
        const bool gt = m > colmax[u];
        colmax[u] = gt ? m : colmax[u];
        argblock[u] = gt ? block_id : argblock[u];
      }
    }
    // Raw rows for the background median, copied while they are in cache.
    for (; sample < num_samples && next_sample < r1; ++sample, next_sample += sample_step) {
      std::memcpy(w.samples.data() + static_cast<size_t>(sample) * width, p.row(next_sample),
                  sizeof(T) * width);
    }
  }
  // The samples outside the blocks read: the background is the whole column's.
  for (int k = 0; k < num_samples; ++k) {
    const int r = sample_step / 2 + k * sample_step;
    if (r >= first * block_rows && r < std::min(height, (last + 1) * block_rows)) continue;
    std::memcpy(w.samples.data() + static_cast<size_t>(k) * width, p.row(r), sizeof(T) * width);
  }
  // The bound on the exact filtered maximum of each column (see the file comment).
  T* __restrict upper = w.upper.data();
  if (!kMedian || width == 1) {
    std::copy_n(colmax, width, upper);
  } else {
    upper[0] = Max(colmax[0], colmax[1]);
    for (int u = 1; u < width - 1; ++u) {
      upper[u] = Max(Max(colmax[u - 1], colmax[u]), colmax[u + 1]);
    }
    upper[width - 1] = Max(colmax[width - 2], colmax[width - 1]);
  }
}

// Lower median of the num_samples rows of `samples`, for every column at once: a bitwise radix
// select (per bit from the top: keep the bit if fewer than rank+1 samples lie below the probe).
template <typename T>
INSITU_INLINE void ColumnMedianBody(const T* __restrict samples, int num_samples, int width,
                                    T* __restrict out, T* __restrict probe, T* __restrict count) {
  const T rank = static_cast<T>((num_samples - 1) / 2);
  std::fill_n(out, width, T{0});
  for (int bit = static_cast<int>(sizeof(T) * 8) - 1; bit >= 0; --bit) {
    const T add = static_cast<T>(1u << bit);
    for (int u = 0; u < width; ++u) {
      probe[u] = static_cast<T>(out[u] | add);
      count[u] = 0;
    }
    for (int j = 0; j < num_samples; ++j) {
      const T* __restrict s = samples + static_cast<size_t>(j) * width;
      for (int u = 0; u < width; ++u) count[u] = static_cast<T>(count[u] + (s[u] < probe[u]));
    }
    for (int u = 0; u < width; ++u) out[u] = count[u] <= rank ? probe[u] : out[u];
  }
}

// ---------------------------------------------------------------------------------------------
// Pass 2 kernels (one group of n columns starting at u0, band rows rlo..rhi).

// tile[(r - rlo) * n + c] = exact 3x3 median at (u0 + c, r), borders replicated (as OpenCV).
// Each input row is sorted horizontally into (lo, mid, hi) triples; the median of nine is then
// median(max of the three lo, median of the three mid, min of the three hi).
template <typename T, bool kMedian>
INSITU_INLINE void TileBody(const Plane<T>& p, int u0, int n, int rlo, int rhi, Work<T>& w) {
  const int rows = rhi - rlo + 1;
  T* __restrict tile = w.tile.data();
  if constexpr (!kMedian) {
    for (int i = 0; i < rows; ++i) std::memcpy(tile + i * n, p.row(rlo + i) + u0, sizeof(T) * n);
  } else {
    T* __restrict pad = w.pad.data();
    T* __restrict lo = w.lo.data();
    T* __restrict mid = w.mid.data();
    T* __restrict hi = w.hi.data();
    const int left = std::max(u0 - 1, 0);
    const int right = std::min(u0 + n, p.width - 1);
    for (int i = 0; i < rows + 2; ++i) {
      const T* src = p.row_clamped(rlo - 1 + i);
      pad[0] = src[left];
      std::memcpy(pad + 1, src + u0, sizeof(T) * n);
      pad[n + 1] = src[right];
      T* __restrict l = lo + i * n;
      T* __restrict m = mid + i * n;
      T* __restrict h = hi + i * n;
      for (int c = 0; c < n; ++c) {
        const T a = pad[c];
        const T b = pad[c + 1];
        const T d = pad[c + 2];
        const T mn = Min(a, b);
        const T mx = Max(a, b);
        l[c] = Min(mn, d);
        h[c] = Max(mx, d);
        m[c] = Max(mn, Min(mx, d));
      }
    }
    for (int i = 0; i < rows; ++i) {
      const T* __restrict l0 = lo + i * n;
      const T* __restrict m0 = mid + i * n;
      const T* __restrict h0 = hi + i * n;
      T* __restrict out = tile + i * n;
      for (int c = 0; c < n; ++c) {
        const T l = Max(Max(l0[c], l0[c + n]), l0[c + 2 * n]);
        const T m = Med3(m0[c], m0[c + n], m0[c + 2 * n]);
        const T h = Min(Min(h0[c], h0[c + n]), h0[c + 2 * n]);
        out[c] = Med3(l, m, h);
      }
    }
  }
}

// flag[i * n + c] = 1 where tile row i of column c is a peak that Decide's pre-test passes
// (rows reach..rows-reach-1, where both rows reach away lie in the tile): at least min_peak,
// above the row before it and not below the row after (the first row of a flat top), and
// min_contrast above the darker of the rows reach away. The thresholds are integers (the
// ceilings of the options'), so the test is the scalar one exactly. count[c]: the column's
// flags (up to 255). Measured: the scalar test over the band took a quarter of a default
// frame's extraction.
template <typename T>
INSITU_INLINE void PeakFlagsBody(const T* __restrict tile, int n, int rows, int reach, T min_peak,
                                 T min_contrast, uint8_t* __restrict flag,
                                 uint8_t* __restrict count) {
  std::fill_n(count, n, uint8_t{0});
  for (int i = reach; i < rows - reach; ++i) {
    const T* __restrict g = tile + static_cast<ptrdiff_t>(i) * n;
    const T* __restrict up = g - n;
    const T* __restrict down = g + n;
    const T* __restrict far_up = g - static_cast<ptrdiff_t>(reach) * n;
    const T* __restrict far_down = g + static_cast<ptrdiff_t>(reach) * n;
    uint8_t* __restrict f = flag + static_cast<ptrdiff_t>(i) * n;
    for (int c = 0; c < n; ++c) {
      const T v = g[c];
      const T side = Min(far_up[c], far_down[c]);
      // v - side >= min_contrast without leaving T: v >= min_contrast and side <= v - it.
      // Bitwise, not short-circuit: one vector compare each.
      const uint8_t peak =
          static_cast<uint8_t>((v >= min_peak) & (v >= min_contrast) & (up[c] < v) &
                               (down[c] <= v) & (side <= static_cast<T>(v - min_contrast)));
      f[c] = peak;
      count[c] = static_cast<uint8_t>(count[c] + (peak & (count[c] < 255)));
    }
  }
}

// The stripe's blocks, by the block maxima of pass 1 (own column, vertical median v): the ridge
// of block b is R(b) = bm(b) - max(bm(b - d), bm(b + d)) (0 where negative; a side beyond the
// frame counts as dark), its height above the brighter of the blocks d away on either side. A
// stripe (a few pixels wide) stands above both; a lit surface wider than 2 d blocks, or its
// edge (a step), does not. Per column: the number of local maxima of R reaching `floor` (up to
// kRidgeSlots + 1), the blocks of the first kRidgeSlots of them, the largest R and its block.
template <typename T>
INSITU_INLINE void RidgeRow(const T* __restrict blocks, int first, int last, int width, int d,
                            int b, T* __restrict out) {
  if (b < first || b > last) {
    std::fill_n(out, width, T{0});
    return;
  }
  const T* __restrict m = blocks + static_cast<size_t>(b) * width;
  const bool has_lo = b - d >= first, has_hi = b + d <= last;
  if (has_lo && has_hi) {
    const T* __restrict lo = blocks + static_cast<size_t>(b - d) * width;
    const T* __restrict hi = blocks + static_cast<size_t>(b + d) * width;
    for (int u = 0; u < width; ++u) {
      const T side = Max(lo[u], hi[u]);
      out[u] = static_cast<T>(Max(m[u], side) - side);  // m - side, 0 when negative
    }
  } else if (has_lo || has_hi) {
    const T* __restrict one = blocks + static_cast<size_t>(has_lo ? b - d : b + d) * width;
    for (int u = 0; u < width; ++u) out[u] = static_cast<T>(Max(m[u], one[u]) - one[u]);
  } else {
    std::copy_n(m, width, out);
  }
}

template <typename T>
INSITU_INLINE void RidgeBody(const T* __restrict blocks, int first, int last, int width, int d,
                             T floor, T* __restrict prev, T* __restrict cur, T* __restrict next,
                             T* __restrict best, T* __restrict best_block,
                             uint8_t* __restrict count, T* __restrict slots) {
  std::fill_n(best, width, T{0});
  std::fill_n(best_block, width, T{0});
  std::fill_n(count, width, uint8_t{0});
  RidgeRow(blocks, first, last, width, d, first - 1, prev);
  RidgeRow(blocks, first, last, width, d, first, cur);
  for (int b = first; b <= last; ++b) {
    RidgeRow(blocks, first, last, width, d, b + 1, next);
    const T id = static_cast<T>(b);
    // Branch-free over the row (the compiler vectorizes it): a local maximum of R reaching
    // the floor counts, takes the next slot and may be the best.
    static_assert(kRidgeSlots == 4);
    T* __restrict s0 = slots;
    T* __restrict s1 = slots + width;
    T* __restrict s2 = slots + 2 * static_cast<size_t>(width);
    T* __restrict s3 = slots + 3 * static_cast<size_t>(width);
    for (int u = 0; u < width; ++u) {
      const T r = cur[u];
      const bool peak = (r >= floor) & (r > prev[u]) & (r >= next[u]);
      const uint8_t c = count[u];
      // (Masks, not selects: GCC if-converts these four only so.)
      const T m0 = static_cast<T>(-static_cast<T>(peak & (c == 0)));
      const T m1 = static_cast<T>(-static_cast<T>(peak & (c == 1)));
      const T m2 = static_cast<T>(-static_cast<T>(peak & (c == 2)));
      const T m3 = static_cast<T>(-static_cast<T>(peak & (c == 3)));
      s0[u] = static_cast<T>((s0[u] & ~m0) | (id & m0));
      s1[u] = static_cast<T>((s1[u] & ~m1) | (id & m1));
      s2[u] = static_cast<T>((s2[u] & ~m2) | (id & m2));
      s3[u] = static_cast<T>((s3[u] & ~m3) | (id & m3));
      count[u] = static_cast<uint8_t>(c + (peak & (c <= kRidgeSlots)));
      const bool better = peak & (r > best[u]);
      best[u] = better ? r : best[u];
      best_block[u] = better ? id : best_block[u];
    }
    T* t = prev;
    prev = cur;
    cur = next;
    next = t;
  }
}

// Instantiations with an AVX2 clone (the default clone is plain x86-64, SSE2).
INSITU_VECTOR_CLONES void Pass1U8(const Plane<uint8_t>& p, Work<uint8_t>& w, int block_rows,
                                  int step, int ns, bool median, int first, int last) {
  if (median) {
    Pass1Body<uint8_t, true>(p, w, block_rows, step, ns, first, last);
  } else {
    Pass1Body<uint8_t, false>(p, w, block_rows, step, ns, first, last);
  }
}
INSITU_VECTOR_CLONES void Pass1U16(const Plane<uint16_t>& p, Work<uint16_t>& w, int block_rows,
                                   int step, int ns, bool median, int first, int last) {
  if (median) {
    Pass1Body<uint16_t, true>(p, w, block_rows, step, ns, first, last);
  } else {
    Pass1Body<uint16_t, false>(p, w, block_rows, step, ns, first, last);
  }
}
INSITU_VECTOR_CLONES void ColumnMedianU8(Work<uint8_t>& w, int ns, int width) {
  ColumnMedianBody<uint8_t>(w.samples.data(), ns, width, w.background.data(), w.probe.data(),
                            w.count.data());
}
INSITU_VECTOR_CLONES void ColumnMedianU16(Work<uint16_t>& w, int ns, int width) {
  ColumnMedianBody<uint16_t>(w.samples.data(), ns, width, w.background.data(), w.probe.data(),
                             w.count.data());
}
INSITU_VECTOR_CLONES void TileU8(const Plane<uint8_t>& p, int u0, int n, int rlo, int rhi,
                                 Work<uint8_t>& w, bool median) {
  if (median) {
    TileBody<uint8_t, true>(p, u0, n, rlo, rhi, w);
  } else {
    TileBody<uint8_t, false>(p, u0, n, rlo, rhi, w);
  }
}
INSITU_VECTOR_CLONES void TileU16(const Plane<uint16_t>& p, int u0, int n, int rlo, int rhi,
                                  Work<uint16_t>& w, bool median) {
  if (median) {
    TileBody<uint16_t, true>(p, u0, n, rlo, rhi, w);
  } else {
    TileBody<uint16_t, false>(p, u0, n, rlo, rhi, w);
  }
}
INSITU_VECTOR_CLONES void RidgeU8(Work<uint8_t>& w, int first, int last, int width, int d,
                                  uint8_t floor) {
  RidgeBody<uint8_t>(w.blocks.data(), first, last, width, d, floor, w.ridge_prev.data(),
                     w.ridge_cur.data(), w.ridge_next.data(), w.ridge.data(), w.ridge_block.data(),
                     w.ridge_count.data(), w.ridge_slots.data());
}
INSITU_VECTOR_CLONES void RidgeU16(Work<uint16_t>& w, int first, int last, int width, int d,
                                   uint16_t floor) {
  RidgeBody<uint16_t>(w.blocks.data(), first, last, width, d, floor, w.ridge_prev.data(),
                      w.ridge_cur.data(), w.ridge_next.data(), w.ridge.data(), w.ridge_block.data(),
                      w.ridge_count.data(), w.ridge_slots.data());
}

inline void Pass1(const Plane<uint8_t>& p, Work<uint8_t>& w, int block_rows, int step, int ns,
                  bool median, int first, int last) {
  Pass1U8(p, w, block_rows, step, ns, median, first, last);
}
inline void Pass1(const Plane<uint16_t>& p, Work<uint16_t>& w, int block_rows, int step, int ns,
                  bool median, int first, int last) {
  Pass1U16(p, w, block_rows, step, ns, median, first, last);
}
inline void ColumnMedian(Work<uint8_t>& w, int ns, int width) {
  ColumnMedianU8(w, ns, width);
}
inline void ColumnMedian(Work<uint16_t>& w, int ns, int width) {
  ColumnMedianU16(w, ns, width);
}
inline void Tile(const Plane<uint8_t>& p, int u0, int n, int rlo, int rhi, Work<uint8_t>& w,
                 bool median) {
  TileU8(p, u0, n, rlo, rhi, w, median);
}
inline void Tile(const Plane<uint16_t>& p, int u0, int n, int rlo, int rhi, Work<uint16_t>& w,
                 bool median) {
  TileU16(p, u0, n, rlo, rhi, w, median);
}
INSITU_VECTOR_CLONES void PeakFlagsU8(const uint8_t* tile, int n, int rows, int reach,
                                      uint8_t min_peak, uint8_t min_contrast, uint8_t* flag,
                                      uint8_t* count) {
  PeakFlagsBody<uint8_t>(tile, n, rows, reach, min_peak, min_contrast, flag, count);
}
INSITU_VECTOR_CLONES void PeakFlagsU16(const uint16_t* tile, int n, int rows, int reach,
                                       uint16_t min_peak, uint16_t min_contrast, uint8_t* flag,
                                       uint8_t* count) {
  PeakFlagsBody<uint16_t>(tile, n, rows, reach, min_peak, min_contrast, flag, count);
}
inline void PeakFlags(const uint8_t* tile, int n, int rows, int reach, uint8_t min_peak,
                      uint8_t min_contrast, uint8_t* flag, uint8_t* count) {
  PeakFlagsU8(tile, n, rows, reach, min_peak, min_contrast, flag, count);
}
inline void PeakFlags(const uint16_t* tile, int n, int rows, int reach, uint16_t min_peak,
                      uint16_t min_contrast, uint8_t* flag, uint8_t* count) {
  PeakFlagsU16(tile, n, rows, reach, min_peak, min_contrast, flag, count);
}
inline void Ridge(Work<uint8_t>& w, int first, int last, int width, int d, int floor) {
  RidgeU8(w, first, last, width, d, static_cast<uint8_t>(std::min(floor, 255)));
}
inline void Ridge(Work<uint16_t>& w, int first, int last, int width, int d, int floor) {
  RidgeU16(w, first, last, width, d, static_cast<uint16_t>(std::min(floor, 65535)));
}

// ---------------------------------------------------------------------------------------------
// Pass 2: per group and per column decisions.

template <typename T>
class ColumnExtractor {
 public:
  ColumnExtractor(const Plane<T>& plane, const StripeOptions& options, int saturation_level,
                  Work<T>& work, StripeResult* result, const StripeWindow* window)
      : p_(plane),
        o_(options),
        w_(work),
        res_(result),
        saturation_(saturation_level),
        window_(window) {
    median_ = options.median_kernel == 3;
    // The block index is stored in a T (one vector lane per column in pass 1).
    block_rows_ = kMinBlockRows;
    while ((p_.height + block_rows_ - 1) / block_rows_ - 1 > std::numeric_limits<T>::max()) {
      block_rows_ *= 2;
    }
    num_blocks_ = (p_.height + block_rows_ - 1) / block_rows_;
    ridge_blocks_ = std::max(1, (kRidgeRows + block_rows_ - 1) / block_rows_);
    reach_ = std::clamp(o_.max_width_px / 4, 4, 16);
    // Refine's window half-width per width at K: kWindowSigmas beam sigmas, a Gaussian's width
    // at k of its peak being 2 sigma sqrt(2 ln(1/k)).
    window_per_width_ = kWindowSigmas / (2.0 * std::sqrt(2.0 * std::log(1.0 / o_.threshold_ratio)));
    ridge_floor_ = std::max(1, static_cast<int>(std::ceil(o_.min_contrast)));
    // PeakFlags' integer thresholds; none when they exceed every sample value.
    const double top = std::numeric_limits<T>::max();
    const double min_peak = std::ceil(o_.min_peak), min_contrast = std::ceil(o_.min_contrast);
    flags_possible_ = min_peak <= top && min_contrast <= top;
    if (flags_possible_) {
      flag_min_peak_ = static_cast<T>(std::max(min_peak, 0.0));
      flag_min_contrast_ = static_cast<T>(std::max(min_contrast, 0.0));
    }
  }

  void Run() {
    const int width = p_.width;
    const int height = p_.height;
    Resize();
    WindowedBlocks();
    const int ns = std::min(height, kBackgroundSamples);
    Pass1(p_, w_, block_rows_, height / ns, ns, median_, first_, last_);
    ColumnMedian(w_, ns, width);
    Ridge(w_, first_, last_, width, ridge_blocks_, RidgeFloor());
    std::fill(w_.widths.begin(), w_.widths.end(), kNaN);
    std::fill(w_.evidence.begin(), w_.evidence.end(), kNaN);
    for (int u0 = 0; u0 < width; u0 += kGroupCols) {
      ProcessRange(u0, std::min(kGroupCols, width - u0), nullptr);
    }
    WidthTest();
    IsolationTest();
  }

 private:
  void Resize() {
    const size_t width = static_cast<size_t>(p_.width);
    w_.acc.resize(width);
    w_.blocks.resize(static_cast<size_t>(num_blocks_) * width);
    w_.colmax.resize(width);
    w_.argblock.resize(width);
    w_.upper.resize(width);
    w_.samples.resize(static_cast<size_t>(kBackgroundSamples) * width);
    w_.background.resize(width);
    w_.probe.resize(width);
    w_.count.resize(width);
    for (auto* v : {&w_.ridge_prev, &w_.ridge_cur, &w_.ridge_next, &w_.ridge, &w_.ridge_block}) {
      v->resize(width);
    }
    w_.ridge_count.resize(width);
    w_.ridge_slots.resize(static_cast<size_t>(kRidgeSlots) * width);
    w_.widths.resize(width);
    w_.evidence.resize(width);
    // Largest band: spread + 2 margins, in blocks, plus a row above and below for the filter.
    const int band_blocks = std::min(num_blocks_, kMaxBlockSpread + 3 + 2 * ridge_blocks_);
    const size_t tile_size =
        (static_cast<size_t>(band_blocks) * block_rows_ + 2 + 2 * reach_) * kGroupCols;
    w_.pad.resize(kGroupCols + 2);
    for (auto* v : {&w_.lo, &w_.mid, &w_.hi, &w_.tile}) v->resize(tile_size);
    w_.peak_flag.resize(tile_size);
    w_.peak_count.resize(kGroupCols);
    w_.exact.resize(static_cast<size_t>(p_.height));
    w_.exact_stamp.assign(static_cast<size_t>(p_.height), 0);
    w_.stamp = 0;
    w_.candidate.resize(kGroupCols);
    w_.seed_block.resize(kGroupCols);
    res_->center.resize(width);
    res_->status.resize(width);
    res_->peak.resize(width);
    res_->base.resize(width);
    res_->width_px.resize(width);
    res_->sigma_px.resize(width);
  }

  // The blocks pass 1 reads: all, or with a window the rows some scan line's window holds, and
  // the blocks a ridge or a band beside them needs. (On a scan's frame the windows span a
  // seventh of the rows; the rest of the frame is never the stripe.)
  void WindowedBlocks() {
    first_ = 0;
    last_ = num_blocks_ - 1;
    if (window_ == nullptr) return;
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    for (size_t u = 0; u < window_->lo.size(); ++u) {
      const float l = window_->lo[u], h = window_->hi[u];
      if (std::isnan(l) || std::isnan(h)) return;  // this line: anywhere
      if (l <= h) lo = std::min<double>(lo, l), hi = std::max<double>(hi, h);
    }
    if (!(lo <= hi)) {  // no line has a window: nothing to look at
      last_ = 0;
      return;
    }
    const int r_lo = static_cast<int>(std::clamp(std::floor(lo), 0.0, p_.height - 1.0));
    const int r_hi = static_cast<int>(std::clamp(std::ceil(hi), 0.0, p_.height - 1.0));
    const int margin = ridge_blocks_ + 2;
    first_ = std::max(0, r_lo / block_rows_ - margin);
    last_ = std::min(num_blocks_ - 1, r_hi / block_rows_ + margin);
  }

  // A ridge at least this high is a stripe candidate: the least contrast a stripe has.
  int RidgeFloor() const { return ridge_floor_; }

  void SetResult(int u, StripeStatus status, int peak, int width_px, float center, int base = 0,
                 float sigma = kNaN) {
    res_->status[u] = status;
    res_->peak[u] = static_cast<uint16_t>(peak);
    res_->base[u] = static_cast<uint16_t>(base);
    res_->width_px[u] = static_cast<uint8_t>(std::clamp(width_px, 0, 255));
    res_->center[u] = center;
    res_->sigma_px[u] = sigma;
  }

  // One column's filtered profile (Decide's): the group's tile over rows tlo..thi, the exact
  // median (Outside, each row once) beyond it. Passed by value, so that Evaluate keeps it in
  // registers.
  struct Profile {
    const ColumnExtractor* x;
    int u;
    const T* col;  // the column in the tile
    int n;         // the tile's stride
    int tlo, thi;
    uint32_t stamp;
    const T* exact;               // Work::exact
    const uint32_t* exact_stamp;  // Work::exact_stamp
    INSITU_INLINE int operator()(int r) const {
      if (r >= tlo && r <= thi) return col[static_cast<ptrdiff_t>(r - tlo) * n];
      return exact_stamp[r] == stamp ? exact[r] : x->Outside(u, r, stamp);
    }
    // Whether rows a..b (a <= b) all lie in the tile, and a pointer to row r there.
    bool InTile(int a, int b) const { return a >= tlo && b <= thi; }
    const T* Row(int r) const { return col + static_cast<ptrdiff_t>(r - tlo) * n; }
  };

  // The exact 3x3 median outside the tile, each row computed once per column (Decide's stamp),
  // kOutsideRows aligned rows at a time: the looks outside the band sweep along the column, and
  // a run of rows shares each row's sorted triple (one sort per row instead of three per value).
  [[gnu::noinline]] T Outside(int u, int r, uint32_t stamp) const {
    const int r0 = r - r % kOutsideRows;
    const int r1 = std::min(r0 + kOutsideRows, p_.height) - 1;
    if (!median_) {
      for (int i = r0; i <= r1; ++i) w_.exact[i] = p_.row(i)[u];
    } else {
      const int ul = std::max(u - 1, 0);
      const int ur = std::min(u + 1, p_.width - 1);
      T lo[kOutsideRows + 2], mid[kOutsideRows + 2], hi[kOutsideRows + 2];
      for (int i = 0; i < r1 - r0 + 3; ++i) {
        const T* row = p_.row_clamped(r0 - 1 + i);
        const T a = row[ul], b = row[u], d = row[ur];
        lo[i] = Min(Min(a, b), d);
        hi[i] = Max(Max(a, b), d);
        mid[i] = Med3(a, b, d);
      }
      for (int i = 0; i <= r1 - r0; ++i) {
        const T l = Max(Max(lo[i], lo[i + 1]), lo[i + 2]);
        const T h = Min(Min(hi[i], hi[i + 1]), hi[i + 2]);
        w_.exact[r0 + i] = Med3(l, Med3(mid[i], mid[i + 1], mid[i + 2]), h);
      }
    }
    std::fill(w_.exact_stamp.begin() + r0, w_.exact_stamp.begin() + r1 + 1, stamp);
    return w_.exact[r];
  }

  // The contiguous run around rp of rows whose filtered value exceeds level(r); dips below it
  // shorter than min_peak_separation_px are noise inside one stripe and are bridged. Stops one
  // row past max_width_px (then too wide).
  template <typename At, typename Level>
  void RunAround(const At& at, int rp, const Level& level, int* rs_out, int* re_out) const {
    const int height = p_.height;
    int ends[2] = {rp, rp};  // rs, re
    for (int side = 0; side < 2; ++side) {
      const int dir = side == 0 ? -1 : 1;
      for (int r = rp + dir, gap = 0; r >= 0 && r < height; r += dir) {
        if (at(r) > level(r)) {
          ends[side] = r;
          gap = 0;
          if (std::abs(r - rp) >= o_.max_width_px) break;
        } else if (++gap >= o_.min_peak_separation_px) {
          break;
        }
      }
    }
    *rs_out = ends[0];
    *re_out = ends[1];
  }

  // The stripe candidate whose peak the filtered profile `at` climbs to from `seed` (see the file
  // comment: local background, threshold above it, centroid, shape).
  template <typename At>
  Candidate Evaluate(int u, int seed, At at) const {
    return EvaluatePeak(u, Climb(seed, at), at);
  }

  // Up from `seed` to its peak, and to the first row of a flat top (one answer whatever the seed
  // on the peak's flank).
  template <typename At>
  int Climb(int seed, At at) const {
    int rp = seed;
    while (rp + 1 < p_.height && at(rp + 1) > at(rp)) ++rp;
    while (rp > 0 && at(rp - 1) >= at(rp)) --rp;
    return rp;
  }

  // The candidate of the peak at rp (Climb's).
  template <typename At>
  Candidate EvaluatePeak(int u, int rp, At at) const {
    const int height = p_.height;
    Candidate c;
    c.rp = rp;
    c.gmax = at(rp);
    if (c.gmax < o_.min_peak) return c;
    // A peak: above the darker of the profile reach_ rows to either side by min_contrast.
    double side = std::numeric_limits<double>::infinity();
    if (rp - reach_ >= 0) side = at(rp - reach_);
    if (rp + reach_ < height) side = std::min<double>(side, at(rp + reach_));
    if (!std::isfinite(side)) side = w_.background[u];
    c.base = side;
    c.contrast = c.gmax - side;
    if (c.contrast < o_.min_contrast) return c;
    // A first background: the darker of the valleys on either side, where the profile stops
    // falling (a rise of half min_contrast, or no new minimum for reach_ rows), at most
    // max_width_px rows out (a profile falling further is too wide, which its run then shows).
    // (Branch-free but for the stop: the new minima of a noisy flank are unpredictable. The
    // rise is compared as an integer, g - low > floor(min_contrast / 2), the same test.)
    double b0 = std::numeric_limits<double>::infinity();
    const int rise = static_cast<int>(std::floor(0.5 * o_.min_contrast));
    for (int dir : {-1, 1}) {
      const int end =
          dir < 0 ? std::max(rp - o_.max_width_px, 0) : std::min(rp + o_.max_width_px, height - 1);
      if (end == rp) continue;  // the frame's border
      int low = c.gmax;
      auto walk = [&](auto value) INSITU_LAMBDA_INLINE {
        int low_row = rp;
        for (int r = rp + dir;; r += dir) {
          const int g = value(r);
          const bool lower = g < low;
          low_row = lower ? r : low_row;
          low = lower ? g : low;
          if ((g - low > rise) | (std::abs(r - low_row) >= reach_) | (r == end)) break;
        }
      };
      if (at.InTile(std::min(rp, end), std::max(rp, end))) {  // the usual case: straight reads
        const T* row = at.Row(rp);
        const ptrdiff_t step = at.n;
        walk([&](int r) INSITU_LAMBDA_INLINE -> int { return row[(r - rp) * step]; });
      } else {
        walk(at);
      }
      b0 = std::min<double>(b0, low);
    }
    if (!std::isfinite(b0)) b0 = side;
    c.base = b0;
    c.contrast = c.gmax - b0;
    if (c.contrast < o_.min_contrast) return c;
    const double k = o_.threshold_ratio;
    const double level0 = b0 + k * c.contrast;
    int rs = rp, re = rp;
    RunAround(
        at, rp, [&](int) { return level0; }, &rs, &re);
    c.rs = rs;
    c.re = re;
    const uint8_t* raw = p_.base + sizeof(T) * u;
    // A run reaching full scale in the raw pixels is clipped; one over max_width_px too wide.
    auto refused = [&](int from, int to) {
      for (int r = from; r <= to; ++r) {
        if (*reinterpret_cast<const T*>(raw + r * p_.stride) >= saturation_) {
          c.status = StripeStatus::kSaturated;
          return true;
        }
      }
      if (to - from + 1 > o_.max_width_px) {
        c.status = StripeStatus::kTooWide;
        return true;
      }
      return false;
    };
    if (refused(rs, re)) return c;
    // The local background: two windows beside the run, as long as the run and half a run away
    // from it (a run above half the peak ends ~1.2 sigma from the centre, so the windows start
    // ~2.4 sigma out, where a Gaussian profile is under 6 % of its peak, the same on both
    // sides), joined by a straight line; their scatter about their means is the local noise.
    const int run = re - rs + 1;
    const int gap = std::max(2, run / 2);
    const int len = std::max(3, run);
    double sum[2] = {0, 0}, sum2[2] = {0, 0}, mid[2] = {0, 0};
    int count[2] = {0, 0};
    for (int side = 0; side < 2; ++side) {
      const int from = side == 0 ? rs - gap - len + 1 : re + gap;
      for (int r = std::max(from, 0); r <= std::min(from + len - 1, height - 1); ++r) {
        const double g = at(r);
        sum[side] += g;
        sum2[side] += g * g;
        mid[side] += r;
        ++count[side];
      }
    }
    double mean[2] = {b0, b0};
    double noise2 = 0.0;
    int dof = 0;
    for (int side = 0; side < 2; ++side) {
      if (count[side] == 0) continue;
      mean[side] = sum[side] / count[side];
      mid[side] /= count[side];
      noise2 += sum2[side] - sum[side] * mean[side];
      dof += count[side] - 1;
    }
    if (count[0] == 0) mean[0] = mean[1], mid[0] = mid[1] - 1.0;
    if (count[1] == 0) mean[1] = mean[0], mid[1] = mid[0] + 1.0;
    noise2 = dof > 0 ? std::max(noise2, 0.0) / dof : 0.0;
    const double slope = (mean[1] - mean[0]) / (mid[1] - mid[0]);
    auto bg = [&](int r) { return mean[0] + slope * (r - mid[0]); };
    c.base = bg(rp);
    c.contrast = c.gmax - c.base;
    if (c.contrast < o_.min_contrast) {
      c.status = StripeStatus::kNone;
      return c;
    }
    // A surface edge under the stripe: the background on its two sides differs by more than the
    // stripe's own height. No straight line is the background there.
    if (count[0] > 0 && count[1] > 0 && std::abs(mean[1] - mean[0]) > c.contrast) {
      c.status = StripeStatus::kBadShape;
      return c;
    }
    const double kc = k * c.contrast;
    auto level = [&](int r) { return bg(r) + kc; };
    RunAround(at, rp, level, &rs, &re);
    c.rs = rs;
    c.re = re;
    if (refused(rs, re)) return c;
    // The run's centroid with weights g_i - K_i (eq. 7 above the threshold): where the stripe
    // is, for the shape tests and the window below.
    double s0 = 0.0, s1 = 0.0;
    for (int r = rs; r <= re; ++r) {
      const double weight = std::max(at(r) - level(r), 0.0);
      s0 += weight;
      s1 += weight * (r - rp);
    }
    if (!(s0 > 0.0)) {
      c.status = StripeStatus::kNone;
      return c;
    }
    const double c0 = rp + s1 / s0;
    // Where the profile crosses K on either side, between the run's end and the next row.
    auto crossing = [&](int inside, int outside) {
      if (outside < 0 || outside >= height) return inside + 0.5 * (outside - inside);
      const double gi = at(inside), go = at(outside), kl = level(inside);
      const double t = gi > go ? std::clamp((gi - kl) / (gi - go), 0.0, 1.0) : 0.5;
      return inside + t * (outside - inside);
    };
    const double x0 = crossing(rs, rs - 1), x1 = crossing(re, re + 1);
    c.width = x1 - x0;
    if (c.width < kMinWidthPx) {  // one pixel: a defect or noise, not a beam
      c.status = StripeStatus::kBadShape;
      return c;
    }
    // A stripe's profile is symmetric about its centre (a Gaussian beam, blurred): its centroid
    // lies mid-way between the crossings, within the noise and speckle. A shoulder (a reflection
    // or a second surface merged into the run) or a pedestal on one side moves it.
    if (std::abs(c0 - 0.5 * (x0 + x1)) > kMaxAsymmetry * c.width + kAsymmetrySlackPx) {
      c.status = StripeStatus::kBadShape;
      return c;
    }
    c.center = c0;
    c.run_weight = s0;  // the run's centroid's sigma, should Refine keep it (RunSigma)
    c.noise2 = noise2;
    c.bg_len = len;
    c.bg_rs = bg(rs);
    c.bg_re = bg(re);
    c.status = StripeStatus::kValid;
    return c;
  }

  // The chosen candidate's centre: eq. (7) over the whole profile, weights g_i - b_i (the
  // stripe's light above the local background), in a window of +-kWindowSigmas beam sigmas
  // about the run's centroid c0 (Evaluate's), the sigma from the width at K (a Gaussian's
  // width at k of its peak is 2 sigma sqrt(2 ln(1/k))). Cutting the profile at K, as c0 does,
  // drops the flanks and makes the centre hang on the peak's value, both of which speckle and
  // noise move: over the matte part's speckle this centre scatters ~0.08 px rms against c0's
  // ~0.14 (tests/integration/stripe_truth_test.cc). The window's edge pixels count by the
  // share of them inside it, so the centre does not lock to the pixel grid as the window
  // slides; it is kept symmetric inside the image. Only the chosen candidate (the window
  // changes no decision): measured 15-20 % of a frame's time when every candidate had it.
  // The run's centroid's 1-sigma: std(U) = n sqrt(sum (r_i - U)^2) / sum(w_i) for independent
  // noise n on each g_i of the run, plus the quantization's 1/12 LSB^2.
  static void RunSigma(Candidate* c) {
    double spread = 0.0;
    for (int r = c->rs; r <= c->re; ++r) spread += (r - c->center) * (r - c->center);
    c->sigma = std::sqrt(c->noise2 + 1.0 / 12.0) * std::sqrt(spread) / c->run_weight;
  }

  void Refine(Candidate* cand, const Profile& at) const {
    Candidate& c = *cand;
    const int height = p_.height;
    const double c0 = c.center;
    const double half = std::min({window_per_width_ * c.width, c0 + 0.5, height - 0.5 - c0});
    // The pixels wholly inside the window, a..b, and the two it cuts (a - 1, b + 1) by share.
    const int a = static_cast<int>(std::ceil(c0 - half + 0.5));
    const int b = static_cast<int>(std::floor(c0 + half - 0.5));
    const double share_lo = std::clamp(a - 0.5 - (c0 - half), 0.0, 1.0);
    const double share_hi = std::clamp(c0 + half - (b + 0.5), 0.0, 1.0);
    const int len = c.bg_len;
    // The background under the window: a line through the lowest point of each of two windows
    // just outside it, each as long as the run. The windows beside the run (for K) hold the
    // stripe's flanks, ~2.4 sigma out; here they would add their light and, as the run's ends
    // step by a pixel, tilt the line, which the wide window turns into a shift. The lowest
    // point, not the mean: a neighbour's light reaching into a window (a second line, a lit
    // edge) lifts its mean but not the valley before it; a room-light gradient puts each
    // window's lowest point at its darker end, where the line then passes.
    const int from[2] = {a - 1 - (share_lo > 0.0) - len + 1, b + 1 + (share_hi > 0.0)};
    const int first = std::max(from[0], 0), last = std::min(from[1] + len - 1, height - 1);
    // Straight reads of the tile where all of it lies there (the usual case), else at().
    if (at.InTile(first, last)) {
      const T* row = at.Row(first);
      const ptrdiff_t step = at.n;
      RefineWith(&c, a, b, share_lo, share_hi, from,
                 [&](int r) INSITU_LAMBDA_INLINE -> int { return row[(r - first) * step]; });
    } else {
      RefineWith(&c, a, b, share_lo, share_hi, from, at);
    }
  }

  template <typename Get>
  INSITU_INLINE void RefineWith(Candidate* cand, int a, int b, double share_lo, double share_hi,
                                const int* from, Get get) const {
    Candidate& c = *cand;
    const int height = p_.height;
    const int len = c.bg_len;
    const double c0 = c.center;
    int low[2] = {std::numeric_limits<int>::max(), std::numeric_limits<int>::max()};
    int low_row[2] = {0, 0};
    bool seen[2] = {false, false};
    for (int side = 0; side < 2; ++side) {
      const int r0 = std::max(from[side], 0), r1 = std::min(from[side] + len - 1, height - 1);
      int lv = std::numeric_limits<int>::max(), lr = 0;
      for (int r = r0; r <= r1; ++r) {
        const int g = get(r);
        lr = g < lv ? r : lr;  // branch-free: noise makes the comparison a coin toss
        lv = g < lv ? g : lv;
      }
      low[side] = lv, low_row[side] = lr, seen[side] = r0 <= r1;
    }
    double ob[2], om[2];
    for (int side = 0; side < 2; ++side) {
      const int other = 1 - side;
      if (seen[side]) {
        ob[side] = low[side], om[side] = low_row[side];
      } else if (seen[other]) {  // the image ends there: the other side's level
        ob[side] = low[other];
        om[side] = low_row[other] + (side == 0 ? -1.0 : 1.0);
      } else {
        ob[side] = side == 0 ? c.bg_rs : c.bg_re;
        om[side] = side == 0 ? c.rs : c.re;
      }
    }
    // A background stepping across the window by more than kMaxBackgroundStep of the stripe's
    // contrast is an edge of the room's light (a lit face beside a shadowed one), which no
    // line follows: the run's centroid, which sees only the stripe's top, stays the centre.
    if (std::abs(ob[1] - ob[0]) > kMaxBackgroundStep * c.contrast) return RunSigma(&c);
    const double slope = om[1] > om[0] ? (ob[1] - ob[0]) / (om[1] - om[0]) : 0.0;
    // The whole pixels a..b: integer sums of g and g t (t = r - a), the line's share in
    // closed form (sums of t and t^2), d = a - c0.
    int64_t sg = 0, sgt = 0;
    for (int r = a; r <= b; ++r) {
      const int g = get(r);
      sg += g;
      sgt += static_cast<int64_t>(g) * (r - a);
    }
    const double n = b - a + 1, d = a - c0;
    const double t1 = n * (n - 1) / 2.0, t2 = (n - 1) * n * (2 * n - 1) / 6.0;
    const double line_a = ob[0] + slope * (a - om[0]);  // the line at row a
    double w0 = sg - (n * line_a + slope * t1);
    double w1 = (sgt + d * sg) - (line_a * (t1 + n * d) + slope * (t2 + d * t1));
    double spread = t2 + 2 * d * t1 + n * d * d;
    // The two pixels the window cuts, by their share.
    for (const auto& [r, share] : {std::pair{a - 1, share_lo}, std::pair{b + 1, share_hi}}) {
      if (!(share > 0.0)) continue;
      const double w = share * (get(r) - (ob[0] + slope * (r - om[0]))), dr = r - c0;
      w0 += w;
      w1 += w * dr;
      spread += share * share * dr * dr;
    }
    if (!(w0 > 0.0)) return RunSigma(&c);  // no light above that line: the run's centroid
    c.center = c0 + w1 / w0;
    // std(U) = n sqrt(sum f_i^2 (r_i - c0)^2) / sum(w_i) for independent noise n on each g_i
    // (U - c0 is a fraction of a pixel: second order), plus the quantization's 1/12 LSB^2.
    c.sigma = std::sqrt(c.noise2 + 1.0 / 12.0) * std::sqrt(spread) / w0;
  }

  // Largest exact value of column u in blocks [w_lo, w_hi] outside [blo, bhi], only looking into
  // blocks whose bound (block maximum of v over columns u-1..u+1) exceeds `floor`; returns `floor`
  // when nothing exceeds it.
  T MaxOutside(const Profile& at, int blo, int bhi, int w_lo, int w_hi, T floor,
               int* row_out) const {
    const int u = at.u;
    if (w_.upper[u] <= floor) return floor;  // nothing in the column exceeds it
    const int ul = median_ ? std::max(u - 1, 0) : u;
    const int ur = median_ ? std::min(u + 1, p_.width - 1) : u;
    T best = floor;
    for (int b = w_lo; b <= w_hi; ++b) {
      if (b >= blo && b <= bhi) continue;
      const T* bm = w_.blocks.data() + static_cast<size_t>(b) * p_.width;
      if (Max(Max(bm[ul], bm[u]), bm[ur]) <= best) continue;
      const int r1 = std::min(p_.height, (b + 1) * block_rows_);
      for (int r = b * block_rows_; r < r1; ++r) {
        const T v = static_cast<T>(at(r));
        if (v > best) {
          best = v;
          *row_out = r;
        }
      }
    }
    return best;
  }

  // Ridge R(b) of column u (RidgeBody's, one block).
  int RidgeAt(int u, int b) const {
    if (b < first_ || b > last_) return 0;
    const auto bm = [&](int i) {
      return i >= first_ && i <= last_
                 ? static_cast<int>(w_.blocks[static_cast<size_t>(i) * p_.width + u])
                 : 0;
    };
    return std::max(0, bm(b) - std::max(bm(b - ridge_blocks_), bm(b + ridge_blocks_)));
  }

  // Columns u0..u0+n-1 (only those with select[c] when select is given), band = the blocks
  // holding their stripe candidates +- ridge_blocks_ + 1.
  void ProcessRange(int u0, int n, const uint8_t* select) {
    int abmin = std::numeric_limits<int>::max();
    int abmax = -1;
    for (int c = 0; c < n; ++c) {
      const int u = u0 + c;
      w_.candidate[c] = 0;
      if (select != nullptr && !select[c]) continue;
      // No exact value of the column exceeds `upper` (see the file comment), and a column with
      // no ridge and nothing above its median by min_contrast holds nothing stripe-like: kNone
      // without filtering (its peak is then the maximum of the vertical median v).
      const double upper = w_.upper[u];
      if (upper < o_.min_peak ||
          (w_.ridge_count[u] == 0 && upper - w_.background[u] < o_.min_contrast)) {
        SetResult(u, StripeStatus::kNone, w_.colmax[u], 0, kNaN);
        continue;
      }
      // The highest ridge; with none, the brightest block (it will prove too wide or flat).
      int ab = w_.ridge_count[u] > 0 ? w_.ridge_block[u] : w_.argblock[u];
      if (window_ != nullptr) {
        int b_lo = first_, b_hi = last_;
        if (!WindowBlocks(u, &b_lo, &b_hi)) {
          SetResult(u, StripeStatus::kNone, 0, 0, kNaN);
          continue;
        }
        // No ridge in it: its best ridge below the floor, or its brightest block (what lies
        // outside the window takes no part).
        if (ab < b_lo || ab > b_hi || w_.ridge_count[u] == 0) ab = BestBlockIn(u, b_lo, b_hi);
      }
      w_.candidate[c] = 1;
      w_.seed_block[c] = static_cast<T>(ab);
      abmin = std::min(abmin, ab);
      abmax = std::max(abmax, ab);
    }
    if (abmax < 0) return;
    if (n > 1 && abmax - abmin > kMaxBlockSpread) {
      // Keep the band short: split the group (a steep or broken stripe).
      // The candidates are the selection of the halves (a copy: the halves reuse the buffers).
      uint8_t selected[kGroupCols];
      std::copy_n(w_.candidate.begin(), n, selected);
      const int half = n / 2;
      ProcessRange(u0, half, selected);
      ProcessRange(u0 + half, n - half, selected + half);
      return;
    }
    // The band reaches one block beyond where a ridge looks: a weaker peak with the candidate
    // (its peak block, or its tail in the next) on one side that far shows no ridge of its own.
    const int blo = std::max(abmin - ridge_blocks_ - 1, first_);
    const int bhi = std::min(abmax + ridge_blocks_ + 1, last_);
    const int rlo = blo * block_rows_;
    const int rhi = std::min(p_.height, (bhi + 1) * block_rows_) - 1;
    // The tile reaches reach_ rows beyond the band: the pre-test's and Evaluate's looks around a
    // peak in the band mostly stay inside it.
    const int tlo = std::max(rlo - reach_, 0);
    const int thi = std::min(rhi + reach_, p_.height - 1);
    const size_t tile_size = static_cast<size_t>(thi - tlo + 3) * n;
    if (tile_size > w_.tile.size()) {  // not expected (Resize() covers the bands), but cheap
      for (auto* v : {&w_.lo, &w_.mid, &w_.hi, &w_.tile}) v->resize(tile_size);
      w_.peak_flag.resize(tile_size);
    }
    Tile(p_, u0, n, tlo, thi, w_, median_);
    const int rows = thi - tlo + 1;
    if (flags_possible_) {
      PeakFlags(w_.tile.data(), n, rows, reach_, flag_min_peak_, flag_min_contrast_,
                w_.peak_flag.data(), w_.peak_count.data());
    } else {  // nothing clears them
      std::fill_n(w_.peak_flag.begin(), static_cast<size_t>(rows) * n, 0);
      std::fill_n(w_.peak_count.begin(), n, 0);
    }
    const T* tile = w_.tile.data();
    for (int c = 0; c < n; ++c) {
      if (w_.candidate[c]) {
        Decide(u0 + c, tile + c, w_.peak_flag.data() + c, w_.peak_count[c], n, tlo, thi, blo, bhi,
               w_.seed_block[c]);
      }
    }
  }

  // One column: its candidate in the band, any other stripe-like run in the band or at another
  // ridge of the column, and the verdict.
  void Decide(int u, const T* col, const uint8_t* flag, int flags, int n, int tlo, int thi, int blo,
              int bhi, int seed_block) {
    const int rlo = blo * block_rows_;  // the band
    const int rhi = std::min(p_.height, (bhi + 1) * block_rows_) - 1;
    // The column's filtered profile: the tile in the band, exact values (each computed once)
    // outside it. By value, so that Evaluate keeps it in registers.
    const uint32_t stamp = ++w_.stamp;
    if (stamp == 0) {  // the stamps wrapped: none is current
      std::fill(w_.exact_stamp.begin(), w_.exact_stamp.end(), 0);
      w_.stamp = 1;
    }
    const Profile at{this, u, col, n, tlo, thi, w_.stamp, w_.exact.data(), w_.exact_stamp.data()};
    // The seed: the brightest row of the seed block.
    const int b0 = seed_block * block_rows_;
    const int b1 = std::min(p_.height, b0 + block_rows_) - 1;
    int seed = b0;
    for (int r = b0 + 1; r <= b1; ++r) {
      if (at(r) > at(seed)) seed = r;
    }
    const Candidate main = Evaluate(u, seed, at);
    // Others: every other peak near the candidate (in the band), at the column's other ridges,
    // and near any of those found outside the band (two stripes, or a reflection: the same
    // light twice). Every valid one is kept; the verdict weighs them all (Verdict).
    std::vector<Candidate>& found = w_.found;
    found.clear();
    if ((main.status == StripeStatus::kValid || main.status == StripeStatus::kSaturated) &&
        Inside(u, main.rp)) {
      found.push_back(main);
    }
    const int near_rows = (ridge_blocks_ + 2) * block_rows_;
    std::vector<int>& offband = w_.offband;
    offband.clear();
    bool collect_offband = true;  // one level: not around those found around them
    // A peak inside the valid candidate's run (or within min_peak_separation_px of it) and no
    // higher is part of that stripe (speckle on its flank): not another candidate.
    const bool main_valid = main.status == StripeStatus::kValid;
    const int part_lo = main.rs - o_.min_peak_separation_px;
    const int part_hi = main.re + o_.min_peak_separation_px;
    // Each peak once: a candidate depends on its peak only.
    std::vector<int>& seen = w_.seen;
    seen.assign(1, main.rp);
    auto consider = [&](int s) {
      const int rp = Climb(s, at);
      // More peaks than kMaxPeaks clear the pre-test only where min_contrast lies below the
      // noise (options for another bit depth): the rest are not looked at, which bounds the
      // time a column takes.
      if (seen.size() > kMaxPeaks || std::find(seen.begin(), seen.end(), rp) != seen.end()) {
        return;
      }
      seen.push_back(rp);
      const Candidate other = EvaluatePeak(u, rp, at);
      if ((other.status != StripeStatus::kValid && other.status != StripeStatus::kSaturated) ||
          !Inside(u, other.rp)) {
        return;
      }
      for (const Candidate& f : found) {
        if (f.rp == other.rp) return;
      }
      if (found.size() >= kMaxCandidates) return;
      // Around a stripe found outside the band, as around the candidate; a much wider one (a
      // lit surface, which Verdict drops) needs no look around.
      if (collect_offband && (other.rp < rlo || other.rp > rhi) &&
          !(main_valid && other.width > kMaxWidthRatio * main.width + kWidthSlackPx)) {
        offband.push_back(other.rp);
      }
      found.push_back(other);
    };
    // Every peak of rows lo..hi (the first row of a flat top) other than the candidate's that
    // clears min_peak and min_contrast against the darker of the profile reach_ rows to either
    // side, as Evaluate's first test does.
    // (In the band's interior PeakFlags has run that test.)
    auto passes = [&](int r) {
      const int g = at(r);
      if (g < o_.min_peak || (r > 0 && at(r - 1) >= g) || (r + 1 < p_.height && at(r + 1) > g)) {
        return false;
      }
      int side = std::numeric_limits<int>::max();
      if (r - reach_ >= 0) side = at(r - reach_);
      if (r + reach_ < p_.height) side = std::min(side, at(r + reach_));
      return side == std::numeric_limits<int>::max() || g - side >= o_.min_contrast;
    };
    auto other_peak = [&](int r) {
      if (r == main.rp || !Inside(u, r)) return;
      if (main_valid && r >= part_lo && r <= part_hi && at(r) <= main.gmax) return;
      consider(r);
    };
    auto peaks_in = [&](int lo, int hi) {  // outside the band
      for (int r = std::max(lo, 0); r <= std::min(hi, p_.height - 1); ++r) {
        if (r >= rlo && r <= rhi) continue;
        if (passes(r)) other_peak(r);
      }
    };
    const int flagged_lo = tlo + reach_, flagged_hi = thi - reach_;
    auto flagged = [&](int r) { return flag[static_cast<ptrdiff_t>(r - tlo) * n] != 0; };
    // Flagged rows all seen without a look when there are none, or one: the candidate's.
    const bool main_flagged = main.rp >= flagged_lo && main.rp <= flagged_hi && flagged(main.rp);
    const bool all_seen = flags == 0 || (flags == 1 && main_flagged);
    for (int r = rlo; r <= rhi; ++r) {
      if (all_seen && r == flagged_lo && flagged_lo <= flagged_hi) {
        r = flagged_hi + 1;  // the unflagged rows only
      }
      if (r > rhi) break;
      const bool peak = r >= flagged_lo && r <= flagged_hi ? flagged(r) : passes(r);
      if (peak) other_peak(r);
    }
    int w_lo = first_, w_hi = last_;
    if (window_ != nullptr) WindowBlocks(u, &w_lo, &w_hi);
    const int ridges = w_.ridge_count[u];
    if (ridges >= 2 || (ridges == 1 && w_.ridge_block[u] != seed_block)) {
      // Pass 1's list of the column's ridges, or (more than it holds) the column's blocks.
      const bool listed = ridges <= kRidgeSlots;
      for (int i = listed ? 0 : w_lo; i <= (listed ? ridges - 1 : w_hi); ++i) {
        const int b =
            listed ? static_cast<int>(w_.ridge_slots[static_cast<size_t>(i) * p_.width + u]) : i;
        if (b < w_lo || b > w_hi || (b >= blo && b <= bhi)) continue;
        if (!listed) {
          const int r = RidgeAt(u, b);
          if (r < RidgeFloor() || r <= RidgeAt(u, b - 1) || r < RidgeAt(u, b + 1)) continue;
        }
        const int r0 = b * block_rows_;
        const int r1 = std::min(p_.height, r0 + block_rows_) - 1;
        int best = r0;
        for (int rr = r0 + 1; rr <= r1; ++rr) {
          if (at(rr) > at(best)) best = rr;
        }
        consider(best);
      }
    }
    // Nothing valid yet: the brightest value outside the band (a defect the median removes can
    // hold the column's brightest block, and two stripes 2 blocks apart hide each other's
    // ridges).
    if (std::none_of(found.begin(), found.end(),
                     [](const Candidate& c) { return c.status == StripeStatus::kValid; })) {
      int row = -1;
      const T floor = static_cast<T>(std::max(0, main.gmax));
      if (MaxOutside(at, blo, bhi, w_lo, w_hi, floor, &row) > main.gmax && row >= 0) {
        consider(row);
      }
    }
    // Around each stripe found outside the band, as the band is around the candidate.
    collect_offband = false;
    for (size_t i = 0; i < offband.size(); ++i) {
      const int r = offband[i];
      peaks_in(r - near_rows, r + near_rows);
    }
    const Candidate* chosen = nullptr;
    const StripeStatus verdict = Verdict(found, &chosen);
    if (verdict == StripeStatus::kTwoPeaks || verdict == StripeStatus::kSaturated) {
      SetResult(u, verdict, main.gmax, main.re - main.rs + 1, kNaN);
      if (verdict == StripeStatus::kSaturated) {  // where the clipped peak is
        for (const Candidate& c : found) {
          if (c.status != StripeStatus::kSaturated) continue;
          w_.evidence[u] = 0.5f * static_cast<float>(c.rs + c.re);
          break;
        }
      }
      return;
    }
    if (chosen == nullptr) {
      // Nothing in the window: a peak outside it is not the stripe, whatever it is.
      const StripeStatus why = Inside(u, main.rp) && main.status != StripeStatus::kValid
                                   ? main.status
                                   : StripeStatus::kNone;
      SetResult(u, why, main.gmax, main.re - main.rs + 1, kNaN);
      return;
    }
    Candidate refined = *chosen;
    Refine(&refined, at);
    const int base = std::max(0, static_cast<int>(std::lround(refined.base)));
    SetResult(u, StripeStatus::kValid, refined.gmax, refined.re - refined.rs + 1,
              static_cast<float>(refined.center), std::min(base, refined.gmax),
              static_cast<float>(refined.sigma));
    w_.widths[u] = static_cast<float>(refined.width);
    w_.evidence[u] = static_cast<float>(refined.center);
  }

  // The scan line's valid candidates weighed: a peak much wider than the narrowest is a lit
  // surface or a blurred reflection, not the beam (the beam is the sharpest light of the
  // scene); of the others, peaks whose runs lie within min_peak_separation_px of the strongest
  // are that stripe, and any other at least second_peak_ratio of its contrast is a second
  // stripe: kTwoPeaks. A clipped peak (saturated) may be the stripe too: beside a valid one it
  // makes two peaks, alone the scan line is kSaturated. Else kValid with *chosen the
  // strongest, or kNone with no candidate.
  StripeStatus Verdict(const std::vector<Candidate>& all, const Candidate** chosen) {
    *chosen = nullptr;
    std::vector<Candidate>& found = w_.valid;
    found.clear();
    bool clipped = false;
    for (const Candidate& c : all) {
      if (c.status == StripeStatus::kValid) found.push_back(c);
      clipped = clipped || c.status == StripeStatus::kSaturated;
    }
    if (found.empty()) return clipped ? StripeStatus::kSaturated : StripeStatus::kNone;
    if (clipped) return StripeStatus::kTwoPeaks;
    double narrowest = std::numeric_limits<double>::infinity();
    for (const Candidate& c : found) narrowest = std::min(narrowest, c.width);
    const double limit = kMaxWidthRatio * narrowest + kWidthSlackPx;
    const Candidate* best = nullptr;
    for (const Candidate& c : found) {
      if (c.width <= limit && (best == nullptr || c.contrast > best->contrast)) best = &c;
    }
    const int sep = o_.min_peak_separation_px;
    for (const Candidate& c : found) {
      if (&c == best || c.width > limit) continue;
      const bool same = c.rs <= best->re + sep && c.re >= best->rs - sep;
      if (!same && c.contrast >= o_.second_peak_ratio * best->contrast) {
        return StripeStatus::kTwoPeaks;
      }
    }
    *chosen = &*std::find_if(all.begin(), all.end(),
                             [&](const Candidate& c) { return c.rp == best->rp; });
    return StripeStatus::kValid;
  }

  // The window's rows for scan line u, as blocks; false if the window excludes the line.
  bool WindowBlocks(int u, int* b_lo, int* b_hi) const {
    const float lo = window_->lo[u], hi = window_->hi[u];
    if (std::isnan(lo) || std::isnan(hi)) return true;
    if (!(lo <= hi)) return false;
    // The rows inside it (as Inside counts them), clamped to the frame before any cast.
    const double first = std::ceil(std::max<double>(lo, 0.0));
    const double last = std::floor(std::min<double>(hi, p_.height - 1));
    if (first > last) return false;
    const int r_lo = static_cast<int>(first), r_hi = static_cast<int>(last);
    *b_lo = r_lo / block_rows_;
    *b_hi = r_hi / block_rows_;
    return true;
  }

  // Whether row r of scan line u lies in the window (always, without one).
  bool Inside(int u, int r) const {
    if (window_ == nullptr) return true;
    const float lo = window_->lo[u], hi = window_->hi[u];
    return std::isnan(lo) || std::isnan(hi) || (r >= lo && r <= hi);
  }

  // The highest ridge of column u among blocks b_lo..b_hi, or their brightest block.
  int BestBlockIn(int u, int b_lo, int b_hi) const {
    int best = -1, best_r = 0, bright = b_lo;
    for (int b = b_lo; b <= b_hi; ++b) {
      const int r = RidgeAt(u, b);
      if (r > best_r) best_r = r, best = b;
      if (w_.blocks[static_cast<size_t>(b) * p_.width + u] >
          w_.blocks[static_cast<size_t>(bright) * p_.width + u]) {
        bright = b;
      }
    }
    return best >= 0 ? best : bright;
  }

  // The stripe is one beam seen by one camera: its width changes slowly along it. A valid
  // column much wider than the frame's stripe (or the width the options give) is a stripe
  // merged with something else.
  void WidthTest() {
    double expected = o_.expected_width_px;
    if (!(expected > 0)) {
      std::vector<float>& sorted = w_.sorted_widths;
      sorted.clear();
      for (float x : w_.widths) {
        if (!std::isnan(x)) sorted.push_back(x);
      }
      if (sorted.size() < kMinWidthSample) return;
      const auto middle = sorted.begin() + static_cast<ptrdiff_t>(sorted.size() / 2);
      std::nth_element(sorted.begin(), middle, sorted.end());
      expected = *middle;
    }
    const double limit = kMaxWidthRatio * expected + kWidthSlackPx;
    for (int u = 0; u < p_.width; ++u) {
      if (w_.widths[u] > limit) Refuse(u);
    }
  }

  void Refuse(int u) {
    w_.evidence[u] = kNaN;
    res_->status[u] = StripeStatus::kBadShape;
    res_->center[u] = kNaN;
    res_->sigma_px[u] = kNaN;
    res_->base[u] = 0;
  }

  // A surface seen by neighbouring scan lines is continuous but at its edges, and an edge
  // parts two runs of centres that each agree. A centre more than kIsolatedPx from where the
  // stripe is on both its sides while those agree with each other is light from somewhere else
  // (a reflection where the stripe itself is too faint to see, beside a glint): not valid.
  // Each side: the median of where the nearest kIsolatedReach scan lines see the stripe (valid
  // centres, and the peaks of saturated ones: clipped, but there), at least one. Repeated
  // until nothing changes (a run of two such centres).
  void IsolationTest() {
    const int n = p_.width;
    std::vector<uint8_t>& refuse = w_.refuse;
    auto side_median = [&](int u, int dir, float* out) {
      float vals[kIsolatedReach];
      int k = 0;
      for (int i = 1; i <= kIsolatedReach; ++i) {
        const int x = u + dir * i;
        if (x < 0 || x >= n) break;
        if (std::isnan(w_.evidence[x])) continue;
        // Insertion into the sorted few.
        int j = k++;
        for (; j > 0 && vals[j - 1] > w_.evidence[x]; --j) vals[j] = vals[j - 1];
        vals[j] = w_.evidence[x];
      }
      if (k < 1) return false;
      *out = k % 2 ? vals[k / 2] : 0.5f * (vals[k / 2 - 1] + vals[k / 2]);
      return true;
    };
    for (int round = 0; round < kIsolatedReach; ++round) {
      refuse.assign(static_cast<size_t>(n), 0);
      bool any = false;
      for (int u = 0; u < n; ++u) {
        if (res_->status[u] != StripeStatus::kValid) continue;
        float left = 0, right = 0;
        if (!side_median(u, -1, &left) || !side_median(u, 1, &right)) continue;
        const float c = res_->center[u];
        if (std::abs(left - right) <= kIsolatedPx && std::abs(c - left) > kIsolatedPx &&
            std::abs(c - right) > kIsolatedPx) {
          refuse[u] = 1;
          any = true;
        }
      }
      if (!any) break;
      for (int u = 0; u < n; ++u) {
        if (refuse[u]) {
          Refuse(u);
          w_.evidence[u] = kNaN;
        }
      }
    }
  }

  const Plane<T>& p_;
  const StripeOptions& o_;
  Work<T>& w_;
  StripeResult* res_;
  int saturation_ = 0;
  bool median_ = true;
  int block_rows_ = kMinBlockRows;
  int num_blocks_ = 0;
  int first_ = 0, last_ = 0;  // the blocks pass 1 has read (WindowedBlocks)
  int ridge_blocks_ = 2;
  int reach_ = 10;
  double window_per_width_ = 1.27;
  int ridge_floor_ = 1;
  bool flags_possible_ = true;
  T flag_min_peak_ = 0, flag_min_contrast_ = 0;
  const StripeWindow* window_;
};

// kRows is run as kColumns on the transposed frame: simple and exactly equivalent; the transpose
// (~0.7 ms for 5 MP 8-bit, 8x8 blocks in registers, 2.5x faster than a tiled byte loop) then
// dominates the extraction.
template <typename T>
void TransposeScalar(const Plane<T>& p, int v0, int v1, int u0, int u1, T* dst) {
  const size_t h = static_cast<size_t>(p.height);
  for (int v = v0; v < v1; ++v) {
    const T* src = p.row(v);
    for (int u = u0; u < u1; ++u) dst[u * h + v] = src[u];
  }
}

// Transposes the 8x8 bytes at src (row stride sstride) into dst (row stride dstride): three
// rounds swapping 4x4, 2x2 and 1x1 sub-blocks inside eight 64-bit words.
inline void Transpose8x8(const uint8_t* src, size_t sstride, uint8_t* dst, size_t dstride) {
  uint64_t x[8];
  for (int i = 0; i < 8; ++i) std::memcpy(&x[i], src + i * sstride, 8);
  for (int i = 0; i < 4; ++i) {
    const uint64_t a = x[i], b = x[i + 4];
    x[i] = (a & 0x00000000FFFFFFFFull) | (b << 32);
    x[i + 4] = (a >> 32) | (b & 0xFFFFFFFF00000000ull);
  }
  for (int i : {0, 1, 4, 5}) {
    const uint64_t a = x[i], b = x[i + 2];
    x[i] = (a & 0x0000FFFF0000FFFFull) | ((b & 0x0000FFFF0000FFFFull) << 16);
    x[i + 2] = ((a >> 16) & 0x0000FFFF0000FFFFull) | (b & 0xFFFF0000FFFF0000ull);
  }
  for (int i : {0, 2, 4, 6}) {
    const uint64_t a = x[i], b = x[i + 1];
    x[i] = (a & 0x00FF00FF00FF00FFull) | ((b & 0x00FF00FF00FF00FFull) << 8);
    x[i + 1] = ((a >> 8) & 0x00FF00FF00FF00FFull) | (b & 0xFF00FF00FF00FF00ull);
  }
  for (int i = 0; i < 8; ++i) std::memcpy(dst + i * dstride, &x[i], 8);
}

template <typename T>
void Transpose(const Plane<T>& p, std::vector<T>* out) {
  const int w = p.width;
  const int h = p.height;
  out->resize(static_cast<size_t>(w) * h);
  T* dst = out->data();
  if constexpr (std::is_same_v<T, uint8_t>) {
    if (std::endian::native == std::endian::little) {
      const int w8 = w - w % 8;
      const int h8 = h - h % 8;
      for (int v = 0; v < h8; v += 8) {
        for (int u = 0; u < w8; u += 8) {
          Transpose8x8(p.row(v) + u, p.stride, dst + static_cast<size_t>(u) * h + v, h);
        }
      }
      TransposeScalar(p, 0, h8, w8, w, dst);
      TransposeScalar(p, h8, h, 0, w, dst);
      return;
    }
  }
  constexpr int kTile = 32;
  for (int v0 = 0; v0 < h; v0 += kTile) {
    for (int u0 = 0; u0 < w; u0 += kTile) {
      TransposeScalar(p, v0, std::min(h, v0 + kTile), u0, std::min(w, u0 + kTile), dst);
    }
  }
}

template <typename T>
Plane<T> MakePlane(const ImageView& image) {
  Plane<T> p;
  p.base = static_cast<const uint8_t*>(image.data);
  p.stride = image.stride_bytes;
  p.width = image.width;
  p.height = image.height;
  return p;
}

template <typename T>
void ExtractTyped(const ImageView& image, StripeDirection direction, const StripeOptions& options,
                  Work<T>& work, StripeResult* result, const StripeWindow* window) {
  Plane<T> plane = MakePlane<T>(image);
  if (direction == StripeDirection::kRows) {
    Transpose(plane, &work.transposed);
    plane.base = reinterpret_cast<const uint8_t*>(work.transposed.data());
    plane.stride = sizeof(T) * static_cast<size_t>(image.height);
    plane.width = image.height;
    plane.height = image.width;
  }
  // Saturation is judged on the raw samples, in the image's own scale (12-bit: 4095).
  const int saturation =
      options.saturation_level > 0 ? options.saturation_level : image.max_value();
  ColumnExtractor<T> extractor(plane, options, saturation, work, result, window);
  extractor.Run();
}

// Horizontal 3-tap median of pixel (u, v): removes single hot pixels from the direction estimate.
template <typename T>
int SampleAt(const Plane<T>& p, int u, int v) {
  const T* row = p.row(v);
  return Med3(row[std::max(u - 1, 0)], row[u], row[std::min(u + 1, p.width - 1)]);
}

template <typename T>
StripeDirection EstimateTyped(const Plane<T>& p, int max_value) {
  // About 160 samples along the longer side (the same step in u and v keeps angles): enough for
  // the axis of a stripe, and ~20k samples on a 5 MP frame keep kAuto cheap next to Extract.
  const int step = std::max(1, std::max(p.width, p.height) / 160);
  const int off = step / 2;
  int64_t vmax = 0;
  int64_t sum = 0;
  int64_t count = 0;
  for (int v = off; v < p.height; v += step) {
    for (int u = off; u < p.width; u += step) {
      const int s = SampleAt(p, u, v);
      vmax = std::max<int64_t>(vmax, s);
      sum += s;
      ++count;
    }
  }
  if (count == 0) return StripeDirection::kColumns;
  // The stripe's samples: ridges, brighter by a third of the way from the mean level to the
  // maximum than the frame kRidgeRows / 2 pixels away on both sides, across or along (a
  // line's samples are ridges across it). A lit face, a white board or a label wider than
  // that, however bright, has none inside, and its edges are steps, not ridges.
  const int d = kRidgeRows / 2;
  const double mean = static_cast<double>(sum) / count;
  const double floor = std::max((vmax - mean) / 3.0, 0.03 * max_value);
  auto ridge = [&](int u, int v) {
    const int s = SampleAt(p, u, v);
    const auto at = [&](int uu, int vv) {
      return uu < 0 || vv < 0 || uu >= p.width || vv >= p.height ? 0 : SampleAt(p, uu, vv);
    };
    return s - std::max(at(u, v - d), at(u, v + d)) >= floor ||
           s - std::max(at(u - d, v), at(u + d, v)) >= floor;
  };
  int64_t n = 0, sx = 0, sy = 0, sxx = 0, syy = 0;
  for (int v = off; v < p.height; v += step) {
    for (int u = off; u < p.width; u += step) {
      if (!ridge(u, v)) continue;
      ++n;
      sx += u;
      sy += v;
      sxx += static_cast<int64_t>(u) * u;
      syy += static_cast<int64_t>(v) * v;
    }
  }
  if (n < 2) return StripeDirection::kColumns;
  const double mu = static_cast<double>(sx) / n;
  const double mv = static_cast<double>(sy) / n;
  const double var_u = static_cast<double>(sxx) / n - mu * mu;
  const double var_v = static_cast<double>(syy) / n - mv * mv;
  // The principal axis angle theta has tan(2 theta) = 2 cov / (var_u - var_v); it lies within
  // 45 degrees of the u axis exactly when var_u >= var_v.
  return var_u >= var_v ? StripeDirection::kColumns : StripeDirection::kRows;
}

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

}  // namespace

const char* StripeStatusName(StripeStatus status) {
  switch (status) {
    case StripeStatus::kValid: return "valid";
    case StripeStatus::kNone: return "none";
    case StripeStatus::kSaturated: return "saturated";
    case StripeStatus::kTwoPeaks: return "two_peaks";
    case StripeStatus::kTooWide: return "too_wide";
    case StripeStatus::kBadShape:
      return "bad_shape";
  }
  return "unknown";
}

StripeOptions StripeOptions::ForBitDepth(int bit_depth) const {
  StripeOptions o = *this;
  if (bit_depth > 8 && bit_depth <= 16) {
    const double scale = ((1 << bit_depth) - 1) / 255.0;
    o.min_peak *= scale;
    o.min_contrast *= scale;
  }
  return o;
}

Status StripeOptions::Validate() const {
  if (direction != StripeDirection::kAuto && direction != StripeDirection::kColumns &&
      direction != StripeDirection::kRows) {
    return InvalidArgument("direction must be kAuto, kColumns or kRows, got " +
                           std::to_string(static_cast<int>(direction)));
  }
  if (!(threshold_ratio > 0.0 && threshold_ratio < 1.0)) {
    return InvalidArgument("threshold_ratio must be in (0, 1), got " + Num(threshold_ratio));
  }
  if (median_kernel != 1 && median_kernel != 3) {
    return InvalidArgument("median_kernel must be 1 or 3, got " + std::to_string(median_kernel));
  }
  if (!(min_peak >= 0.0) || !std::isfinite(min_peak)) {
    return InvalidArgument("min_peak must be finite and >= 0, got " + Num(min_peak));
  }
  if (!(min_contrast >= 0.0) || !std::isfinite(min_contrast)) {
    return InvalidArgument("min_contrast must be finite and >= 0, got " + Num(min_contrast));
  }
  // width_px is a uint8_t.
  if (!(second_peak_ratio >= 0.0 && second_peak_ratio <= 1.0)) {
    return InvalidArgument("second_peak_ratio must be in [0, 1], got " +
                           std::to_string(second_peak_ratio));
  }
  if (max_width_px < 1 || max_width_px > 255) {
    return InvalidArgument("max_width_px must be in [1, 255], got " + std::to_string(max_width_px));
  }
  if (min_peak_separation_px < 1 || min_peak_separation_px > 255) {
    return InvalidArgument("min_peak_separation_px must be in [1, 255], got " +
                           std::to_string(min_peak_separation_px));
  }
  if (!(expected_width_px >= 0.0) || !std::isfinite(expected_width_px) ||
      expected_width_px > 255.0) {
    return InvalidArgument("expected_width_px must be in [0, 255] (0: the frame's own), got " +
                           Num(expected_width_px));
  }
  if (saturation_level < 0 || saturation_level > 65535) {
    return InvalidArgument("saturation_level must be in [0, 65535] (0: full scale), got " +
                           std::to_string(saturation_level));
  }
  return Status::Ok();
}

int StripeResult::valid_count() const {
  return static_cast<int>(std::count(status.begin(), status.end(), StripeStatus::kValid));
}

struct StripeExtractor::Scratch {
  Work<uint8_t> w8;
  Work<uint16_t> w16;
};

StripeExtractor::StripeExtractor(const StripeOptions& options)
    : options_(options), scratch_(std::make_unique<Scratch>()) {}

StripeExtractor::~StripeExtractor() = default;

namespace {

Status CheckImage(const ImageView& image) {
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    return InvalidArgument("stripe extraction needs a non-empty image, got " +
                           std::to_string(image.width) + " x " + std::to_string(image.height) +
                           (image.data == nullptr ? " without data" : ""));
  }
  if (image.bit_depth != 8 && (image.bit_depth < 10 || image.bit_depth > 16)) {
    return InvalidArgument("bit_depth must be 8 or 10..16, got " + std::to_string(image.bit_depth));
  }
  if (image.format != PixelFormat::kMono) {
    return InvalidArgument(std::string("a ") + PixelFormatName(image.format) +
                           " frame: the stripe extractor reads one gray plane; reduce the frame "
                           "to the laser's colour channel first (vision::StripePlane)");
  }
  const size_t row_bytes = static_cast<size_t>(image.width) * (image.is_8bit() ? 1 : 2);
  if (image.stride_bytes < row_bytes) {
    return InvalidArgument("stride_bytes " + std::to_string(image.stride_bytes) +
                           " is less than a row (" + std::to_string(row_bytes) + " bytes)");
  }
  if (!image.is_8bit() && (image.stride_bytes % 2 != 0 ||
                           reinterpret_cast<uintptr_t>(image.data) % alignof(uint16_t) != 0)) {
    return InvalidArgument("16-bit samples need 2-byte aligned data and stride");
  }
  return Status::Ok();
}

}  // namespace

Status StripeExtractor::Extract(const ImageView& image, StripeResult* result,
                                const StripeWindow* window) {
  INSITU_RETURN_IF_ERROR(options_.Validate().Prefixed("StripeOptions"));
  if (result == nullptr) return InvalidArgument("Extract: result is null");
  INSITU_RETURN_IF_ERROR(CheckImage(image));
  StripeDirection direction = options_.direction;
  if (window != nullptr) {
    if (direction == StripeDirection::kAuto) {
      return InvalidArgument("a stripe window needs the direction (columns or rows), not auto");
    }
    const size_t lines =
        static_cast<size_t>(direction == StripeDirection::kColumns ? image.width : image.height);
    if (window->lo.size() != lines || window->hi.size() != lines) {
      return InvalidArgument("the stripe window has " + std::to_string(window->lo.size()) +
                             " and " + std::to_string(window->hi.size()) + " limits for " +
                             std::to_string(lines) + " scan lines");
    }
  }
  if (direction == StripeDirection::kAuto) direction = EstimateStripeDirection(image);
  result->direction = direction;
  if (image.is_8bit()) {
    ExtractTyped<uint8_t>(image, direction, options_, scratch_->w8, result, window);
  } else {
    ExtractTyped<uint16_t>(image, direction, options_, scratch_->w16, result, window);
  }
  return Status::Ok();
}

Result<ImageView> StripePlane(const ImageView& image, ColourChannel channel, Image* scratch) {
  if (image.format == PixelFormat::kMono) return image;
  INSITU_RETURN_IF_ERROR(ReduceToChannel(image, channel, scratch));
  return scratch->view();
}

StripeDirection EstimateStripeDirection(const ImageView& image) {
  if (!CheckImage(image).ok()) return StripeDirection::kColumns;
  if (image.is_8bit()) return EstimateTyped(MakePlane<uint8_t>(image), image.max_value());
  return EstimateTyped(MakePlane<uint16_t>(image), image.max_value());
}

}  // namespace insitu::vision
