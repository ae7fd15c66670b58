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
// Pass 2 works on groups of kGroupCols columns whose stripes lie in nearby blocks: it computes the
// exact 3x3 median m only in the band of blocks around the stripes (vectorized across the group's
// columns, sorted-triple method), then per column: gmax, K = k * gmax, the contiguous run above K
// around the maximum, the gray centroid of eq. (7), saturation on the raw pixels of the run, and
// a second peak as any other pixel above K in the band or, through the bound, outside it
// (confirmed on exact medians). Rare cases are redone with a wider band: a run reaching the band's
// edge (wide stripes) and a column whose exact maximum may lie outside its band (a two-pixel
// defect can pull the maximum of v away from the stripe; the 3x3 median removes it).
//
// The scan line's background for min_contrast is the median of the raw profile sampled on
// kBackgroundSamples evenly spaced rows (an exact median of the sample, computed for all columns
// at once by a bitwise radix select); the stripe occupies a few percent of a scan line, so this
// estimates the profile median to a fraction of the noise.
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
// Blocks per superblock: the far-peak test of a group reads superblock maxima (a small table that
// stays in cache) instead of every block of its columns, which measured 3x slower (cache misses).
constexpr int kSuperBlocks = 8;
// Rows beyond the ends of the run where the local background under a stripe is read: a run
// above K = gmax / 2 ends ~1.2 sigma from the centre, so 3 more pixels (sigma ~1.5 px) are
// ~3 sigma out, where the stripe adds under 1% of its peak.
constexpr int kBaseOffset = 3;
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

// Scratch buffers for one sample type; sized on the first frame and reused.
template <typename T>
struct Work {
  std::vector<T> acc;         // W: pass 1 running block maximum of v (generic blocks)
  std::vector<T> blocks;      // nb x W: block maximum of v
  std::vector<T> supers;      // ceil(nb / kSuperBlocks) x W: superblock maximum of v
  std::vector<T> colmax;      // W: maximum of v over the column
  std::vector<T> argblock;    // W: first block holding colmax
  std::vector<T> upper;       // W: colmax over u-1..u+1, bounds the exact gmax
  std::vector<T> samples;     // kBackgroundSamples x W raw rows
  std::vector<T> background;  // W
  std::vector<T> probe;       // W, radix select scratch
  std::vector<T> count;       // W, radix select scratch
  // Pass 2, one group.
  std::vector<T> pad, lo, mid, hi, tile;
  std::vector<T> gmax, kint, farmax, farown, part;
  std::vector<uint16_t> argrow, above;
  std::vector<uint8_t> candidate, select;
  std::vector<std::pair<int, int>> retry;  // (column, forced block or -1) to redo, wider band
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
template <typename T, bool kMedian, bool kFirstOfSuper>
INSITU_INLINE void Block8(const T* const* rows, T* __restrict out, T* __restrict super,
                          T* __restrict colmax, T* __restrict argblock, T block_id, int n) {
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
    super[u] = kFirstOfSuper ? m : Max(super[u], m);
    const bool gt = m > colmax[u];
    colmax[u] = gt ? m : colmax[u];
    argblock[u] = gt ? block_id : argblock[u];
  }
}

template <typename T, bool kMedian>
INSITU_INLINE void Pass1Body(const Plane<T>& p, Work<T>& w, int block_rows, int sample_step,
                             int num_samples) {
  const int width = p.width;
  const int height = p.height;
  const int num_blocks = (height + block_rows - 1) / block_rows;
  T* __restrict acc = w.acc.data();
  T* __restrict colmax = w.colmax.data();
  T* __restrict argblock = w.argblock.data();
  std::fill_n(colmax, width, T{0});
  std::fill_n(argblock, width, T{0});
  int next_sample = sample_step / 2;
  int sample = 0;
  for (int b = 0; b < num_blocks; ++b) {
    const int r0 = b * block_rows;
    const int r1 = std::min(height, r0 + block_rows);
    const T block_id = static_cast<T>(b);  // fits: see ColumnExtractor()
    T* __restrict out = w.blocks.data() + static_cast<size_t>(b) * width;
    T* __restrict super = w.supers.data() + static_cast<size_t>(b / kSuperBlocks) * width;
    const bool first = b % kSuperBlocks == 0;
    if (r1 - r0 == 8) {
      const T* rows[10];
      for (int i = 0; i < 10; ++i) rows[i] = p.row_clamped(r0 - 1 + i);
      if (first) {
        Block8<T, kMedian, true>(rows, out, super, colmax, argblock, block_id, width);
      } else {
        Block8<T, kMedian, false>(rows, out, super, colmax, argblock, block_id, width);
      }
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
        super[u] = first ? m : Max(super[u], m);
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
  // Column maximum of the band and its first row.
  T* __restrict gmax = w.gmax.data();
  uint16_t* __restrict argrow = w.argrow.data();
  std::copy_n(tile, n, gmax);
  std::fill_n(argrow, n, uint16_t{0});
  for (int i = 1; i < rows; ++i) {
    const T* __restrict t = tile + i * n;
    const uint16_t id = static_cast<uint16_t>(i);
    for (int c = 0; c < n; ++c) {
      const bool gt = t[c] > gmax[c];
      gmax[c] = gt ? t[c] : gmax[c];
      argrow[c] = gt ? id : argrow[c];
    }
  }
}

// above[c] = number of band rows with m > kint[c]; farmax[c] = the bound on m outside the band.
// kN > 0 fixes the group width at compile time: these loops run once per band row or block with
// only 64 columns, where a runtime trip count costs more than the work.
template <typename T, int kN, bool kMedian>
INSITU_INLINE void CountBodyN(const T* __restrict blocks, const T* __restrict supers, int width,
                              int num_blocks, int u0, int n_runtime, int rows, int blo, int bhi,
                              Work<T>& w) {
  const int n = kN > 0 ? kN : n_runtime;
  const T* __restrict tile = w.tile.data();
  const T* __restrict kint = w.kint.data();
  uint16_t* __restrict above = w.above.data();
  T* __restrict part = w.part.data();
  T* __restrict farmax = w.farmax.data();
  std::fill_n(above, n, uint16_t{0});
  // Counts in T (one lane per column) over chunks short enough not to overflow it.
  constexpr int kChunk = std::numeric_limits<T>::max();
  for (int i0 = 0; i0 < rows; i0 += kChunk) {
    const int i1 = std::min(rows, i0 + kChunk);
    std::fill_n(part, n, T{0});
    for (int i = i0; i < i1; ++i) {
      const T* __restrict t = tile + i * n;
      for (int c = 0; c < n; ++c) part[c] = static_cast<T>(part[c] + (t[c] > kint[c]));
    }
    for (int c = 0; c < n; ++c) above[c] = static_cast<uint16_t>(above[c] + part[c]);
  }
  // Superblocks clear of the band by their maxima, those overlapping it by their blocks; the
  // tables hold own-column maxima of v, so the bound on m takes columns u-1..u+1 (lo..hi with
  // the border replicated, as the filter does).
  const int lo = std::max(u0 - 1, 0);
  const int hi = std::min(u0 + n, width - 1);
  const int span = hi - lo + 1;
  T* __restrict own = w.farown.data();
  std::fill_n(own, span, T{0});
  const int num_supers = (num_blocks + kSuperBlocks - 1) / kSuperBlocks;
  for (int sb = 0; sb < num_supers; ++sb) {
    const int b0 = sb * kSuperBlocks;
    const int b1 = std::min(num_blocks, b0 + kSuperBlocks) - 1;
    if (b1 < blo || b0 > bhi) {
      const T* __restrict sm = supers + static_cast<size_t>(sb) * width + lo;
      for (int c = 0; c < span; ++c) own[c] = Max(own[c], sm[c]);
      continue;
    }
    for (int b = b0; b <= b1; ++b) {
      if (b >= blo && b <= bhi) continue;
      const T* __restrict bm = blocks + static_cast<size_t>(b) * width + lo;
      for (int c = 0; c < span; ++c) own[c] = Max(own[c], bm[c]);
    }
  }
  // own[i] is column lo + i; farmax[c] is column u0 + c.
  for (int c = 0; c < n; ++c) {
    const int u = u0 + c;
    const int left = std::max(u - 1, 0) - lo;
    const int right = std::min(u + 1, width - 1) - lo;
    farmax[c] = kMedian ? Max(Max(own[left], own[u - lo]), own[right]) : own[u - lo];
  }
}

template <typename T>
INSITU_INLINE void CountBody(const T* __restrict blocks, const T* __restrict supers, int width,
                             int num_blocks, int u0, int n, int rows, int blo, int bhi, bool median,
                             Work<T>& w) {
  if (n == kGroupCols) {
    if (median) {
      CountBodyN<T, kGroupCols, true>(blocks, supers, width, num_blocks, u0, n, rows, blo, bhi, w);
    } else {
      CountBodyN<T, kGroupCols, false>(blocks, supers, width, num_blocks, u0, n, rows, blo, bhi, w);
    }
  } else if (median) {
    CountBodyN<T, 0, true>(blocks, supers, width, num_blocks, u0, n, rows, blo, bhi, w);
  } else {
    CountBodyN<T, 0, false>(blocks, supers, width, num_blocks, u0, n, rows, blo, bhi, w);
  }
}

// Instantiations with an AVX2 clone (the default clone is plain x86-64, SSE2).
INSITU_VECTOR_CLONES void Pass1U8(const Plane<uint8_t>& p, Work<uint8_t>& w, int block_rows,
                                  int step, int ns, bool median) {
  if (median) {
    Pass1Body<uint8_t, true>(p, w, block_rows, step, ns);
  } else {
    Pass1Body<uint8_t, false>(p, w, block_rows, step, ns);
  }
}
INSITU_VECTOR_CLONES void Pass1U16(const Plane<uint16_t>& p, Work<uint16_t>& w, int block_rows,
                                   int step, int ns, bool median) {
  if (median) {
    Pass1Body<uint16_t, true>(p, w, block_rows, step, ns);
  } else {
    Pass1Body<uint16_t, false>(p, w, block_rows, step, ns);
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
INSITU_VECTOR_CLONES void CountU8(int width, int num_blocks, int u0, int n, int rows, int blo,
                                  int bhi, bool median, Work<uint8_t>& w) {
  CountBody<uint8_t>(w.blocks.data(), w.supers.data(), width, num_blocks, u0, n, rows, blo, bhi,
                     median, w);
}
INSITU_VECTOR_CLONES void CountU16(int width, int num_blocks, int u0, int n, int rows, int blo,
                                   int bhi, bool median, Work<uint16_t>& w) {
  CountBody<uint16_t>(w.blocks.data(), w.supers.data(), width, num_blocks, u0, n, rows, blo, bhi,
                      median, w);
}

inline void Pass1(const Plane<uint8_t>& p, Work<uint8_t>& w, int block_rows, int step, int ns,
                  bool median) {
  Pass1U8(p, w, block_rows, step, ns, median);
}
inline void Pass1(const Plane<uint16_t>& p, Work<uint16_t>& w, int block_rows, int step, int ns,
                  bool median) {
  Pass1U16(p, w, block_rows, step, ns, median);
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
inline void Count(int width, int nb, int u0, int n, int rows, int blo, int bhi, bool median,
                  Work<uint8_t>& w) {
  CountU8(width, nb, u0, n, rows, blo, bhi, median, w);
}
inline void Count(int width, int nb, int u0, int n, int rows, int blo, int bhi, bool median,
                  Work<uint16_t>& w) {
  CountU16(width, nb, u0, n, rows, blo, bhi, median, w);
}

// ---------------------------------------------------------------------------------------------
// Pass 2: per group and per column decisions.

template <typename T>
class ColumnExtractor {
 public:
  ColumnExtractor(const Plane<T>& plane, const StripeOptions& options, int saturation_level,
                  Work<T>& work, StripeResult* result)
      : p_(plane), o_(options), w_(work), res_(result), saturation_(saturation_level) {
    median_ = options.median_kernel == 3;
    // The block index is stored in a T (one vector lane per column in pass 1).
    block_rows_ = kMinBlockRows;
    while ((p_.height + block_rows_ - 1) / block_rows_ - 1 > std::numeric_limits<T>::max()) {
      block_rows_ *= 2;
    }
    num_blocks_ = (p_.height + block_rows_ - 1) / block_rows_;
    // A margin that holds any run that is not too wide, plus the gap that ends it.
    wide_margin_ =
        (o_.max_width_px + o_.min_peak_separation_px + 2 + block_rows_ - 1) / block_rows_ + 1;
  }

  void Run() {
    const int width = p_.width;
    const int height = p_.height;
    Resize();
    const int ns = std::min(height, kBackgroundSamples);
    Pass1(p_, w_, block_rows_, height / ns, ns, median_);
    ColumnMedian(w_, ns, width);
    for (int u0 = 0; u0 < width; u0 += kGroupCols) {
      const int n = std::min(kGroupCols, width - u0);
      w_.retry.clear();
      ProcessRange(u0, n, /*margin=*/1, /*forced_block=*/-1, /*select=*/nullptr);
      if (w_.retry.empty()) continue;
      // Columns whose run reached the band edge (wide stripes) are redone together with a band
      // that holds any acceptable run; a column whose exact maximum lies outside its band is
      // redone alone, around that maximum.
      std::fill_n(w_.select.begin(), n, uint8_t{0});
      bool any_edge = false;
      for (size_t i = 0; i < w_.retry.size(); ++i) {
        const auto [u, forced] = w_.retry[i];
        if (forced < 0) {
          w_.select[u - u0] = 1;
          any_edge = true;
        }
      }
      if (any_edge) ProcessRange(u0, n, wide_margin_, -1, w_.select.data());
      // Including those the wide pass just added; these calls add none (forced, wide).
      for (size_t i = 0; i < w_.retry.size(); ++i) {
        const auto [u, forced] = w_.retry[i];
        if (forced >= 0) ProcessRange(u, 1, wide_margin_, forced, nullptr);
      }
    }
  }

 private:
  void Resize() {
    const size_t width = static_cast<size_t>(p_.width);
    w_.acc.resize(width);
    w_.blocks.resize(static_cast<size_t>(num_blocks_) * width);
    w_.supers.resize(static_cast<size_t>((num_blocks_ + kSuperBlocks - 1) / kSuperBlocks) * width);
    w_.colmax.resize(width);
    w_.argblock.resize(width);
    w_.upper.resize(width);
    w_.samples.resize(static_cast<size_t>(kBackgroundSamples) * width);
    w_.background.resize(width);
    w_.probe.resize(width);
    w_.count.resize(width);
    // Largest band: spread + 2 margins, in blocks, plus a row above and below for the filter.
    const int band_blocks =
        std::min(num_blocks_, kMaxBlockSpread + 1 + 2 * std::max(wide_margin_, 1));
    const size_t tile_size = (static_cast<size_t>(band_blocks) * block_rows_ + 2) * kGroupCols;
    w_.pad.resize(kGroupCols + 2);
    for (auto* v : {&w_.lo, &w_.mid, &w_.hi, &w_.tile}) v->resize(tile_size);
    for (auto* v : {&w_.gmax, &w_.kint, &w_.farmax, &w_.part}) v->resize(kGroupCols);
    w_.farown.resize(kGroupCols + 2);
    w_.argrow.resize(kGroupCols);
    w_.above.resize(kGroupCols);
    w_.candidate.resize(kGroupCols);
    w_.select.resize(kGroupCols);
    res_->center.resize(width);
    res_->status.resize(width);
    res_->peak.resize(width);
    res_->base.resize(width);
    res_->width_px.resize(width);
  }

  void SetResult(int u, StripeStatus status, int peak, int width_px, float center, int base = 0) {
    res_->status[u] = status;
    res_->peak[u] = static_cast<uint16_t>(peak);
    res_->base[u] = static_cast<uint16_t>(base);
    res_->width_px[u] = static_cast<uint8_t>(std::clamp(width_px, 0, 255));
    res_->center[u] = center;
  }

  bool IsNone(double peak, int u) const {
    return peak < o_.min_peak || peak - static_cast<double>(w_.background[u]) < o_.min_contrast;
  }

  // Exact filtered value at one pixel (slow path).
  T ExactAt(int u, int r) const {
    if (!median_) return p_.row(r)[u];
    const int ul = std::max(u - 1, 0);
    const int ur = std::min(u + 1, p_.width - 1);
    T lo = std::numeric_limits<T>::min();
    T hi = std::numeric_limits<T>::max();
    T m[3];
    for (int k = 0; k < 3; ++k) {
      const T* row = p_.row_clamped(r - 1 + k);
      const T a = row[ul];
      const T b = row[u];
      const T d = row[ur];
      lo = Max(lo, Min(Min(a, b), d));
      hi = Min(hi, Max(Max(a, b), d));
      m[k] = Med3(a, b, d);
    }
    return Med3(lo, Med3(m[0], m[1], m[2]), hi);
  }

  // Largest exact value of column u outside blocks [blo, bhi], only looking into blocks whose
  // bound (block maximum of v over columns u-1..u+1) exceeds `floor`; returns `floor` when
  // nothing exceeds it.
  T MaxOutside(int u, int blo, int bhi, T floor, int* row_out) const {
    const int ul = median_ ? std::max(u - 1, 0) : u;
    const int ur = median_ ? std::min(u + 1, p_.width - 1) : u;
    T best = floor;
    for (int b = 0; b < num_blocks_; ++b) {
      if (b >= blo && b <= bhi) continue;
      const T* bm = w_.blocks.data() + static_cast<size_t>(b) * p_.width;
      if (Max(Max(bm[ul], bm[u]), bm[ur]) <= best) continue;
      const int r1 = std::min(p_.height, (b + 1) * block_rows_);
      for (int r = b * block_rows_; r < r1; ++r) {
        const T v = ExactAt(u, r);
        if (v > best) {
          best = v;
          *row_out = r;
        }
      }
    }
    return best;
  }

  // True if column u holds, besides the stripe's run rs..re, another run above K that competes
  // with it: at most max_width_px long (bridging dips as the main run does) and peaking at
  // second_peak_ratio * gmax or more. A longer or clearly weaker run is a surface lit by
  // ambient light (the top of a part, beside a weak stripe on a dark plate, or a corner of it),
  // not a second stripe, and leaves the stripe valid. Exact medians are computed only in blocks
  // whose bound exceeds K; the others count as rows below K.
  bool SecondStripe(int u, int rs, int re, T kint, T gmax) const {
    const int ul = median_ ? std::max(u - 1, 0) : u;
    const int ur = median_ ? std::min(u + 1, p_.width - 1) : u;
    const double min_peak = o_.second_peak_ratio * gmax;
    int start = -1;
    int last = -1;
    T peak = 0;
    auto closes_stripe = [&]() {  // the open run start..last, if any, is another stripe
      return start >= 0 && (last < rs || start > re) && last - start + 1 <= o_.max_width_px &&
             peak >= min_peak;
    };
    for (int b = 0; b < num_blocks_; ++b) {
      const int r0 = b * block_rows_;
      const int r1 = std::min(p_.height, r0 + block_rows_);
      const T* bm = w_.blocks.data() + static_cast<size_t>(b) * p_.width;
      const bool may_exceed = Max(Max(bm[ul], bm[u]), bm[ur]) > kint;
      for (int r = r0; r < r1; ++r) {
        const T m = may_exceed ? ExactAt(u, r) : T{0};
        if (m > kint) {
          if (start < 0) {
            start = r;
            peak = 0;
          }
          last = r;
          peak = Max(peak, m);
        } else if (start >= 0 && r - last >= o_.min_peak_separation_px) {
          if (closes_stripe()) return true;
          start = -1;
        }
      }
    }
    return closes_stripe();
  }

  // Columns u0..u0+n-1 (only those with select[c] when select is given), band = the blocks
  // holding their stripes (forced_block if >= 0) +- margin blocks.
  void ProcessRange(int u0, int n, int margin, int forced_block, const uint8_t* select) {
    int abmin = std::numeric_limits<int>::max();
    int abmax = -1;
    for (int c = 0; c < n; ++c) {
      const int u = u0 + c;
      w_.candidate[c] = 0;
      if (select != nullptr && !select[c]) continue;
      // No exact value of the column exceeds `upper` (see the file comment), so this decides
      // kNone for empty scan lines without filtering them (their peak is then the maximum of
      // the vertical median v: the 3x3 median is never computed there).
      if (IsNone(w_.upper[u], u)) {
        SetResult(u, StripeStatus::kNone, w_.colmax[u], 0, kNaN);
        continue;
      }
      w_.candidate[c] = 1;
      const int ab = forced_block >= 0 ? forced_block : w_.argblock[u];
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
      ProcessRange(u0, half, margin, forced_block, selected);
      ProcessRange(u0 + half, n - half, margin, forced_block, selected + half);
      return;
    }
    const int blo = std::max(abmin - margin, 0);
    const int bhi = std::min(abmax + margin, num_blocks_ - 1);
    const int rlo = blo * block_rows_;
    const int rhi = std::min(p_.height, (bhi + 1) * block_rows_) - 1;
    const size_t tile_size = static_cast<size_t>(rhi - rlo + 3) * n;
    if (tile_size > w_.tile.size()) {  // not expected (Resize() covers the bands), but cheap
      for (auto* v : {&w_.lo, &w_.mid, &w_.hi, &w_.tile}) v->resize(tile_size);
    }
    Tile(p_, u0, n, rlo, rhi, w_, median_);

    const double k = o_.threshold_ratio;
    for (int c = 0; c < n; ++c) {
      // m > K  <=>  m > floor(K) for integer m (the cast truncates: K >= 0). Non-candidates
      // never count.
      w_.kint[c] = w_.candidate[c] ? static_cast<T>(k * w_.gmax[c]) : std::numeric_limits<T>::max();
    }
    Count(p_.width, num_blocks_, u0, n, rhi - rlo + 1, blo, bhi, median_, w_);

    const T* tile = w_.tile.data();
    for (int c = 0; c < n; ++c) {
      if (!w_.candidate[c]) continue;
      const int u = u0 + c;
      const T gmax = w_.gmax[c];
      // A larger exact value may lie outside the band only where the bound exceeds gmax (e.g. a
      // two-pixel defect pulled the vertical-median maximum away from the stripe). Then the
      // column is redone around that value, once.
      if (w_.farmax[c] > gmax && forced_block < 0) {
        int row = -1;
        if (MaxOutside(u, blo, bhi, gmax, &row) > gmax) {
          w_.retry.emplace_back(u, row / block_rows_);
          continue;
        }
      }
      if (IsNone(gmax, u)) {
        SetResult(u, StripeStatus::kNone, gmax, 0, kNaN);
        continue;
      }
      const T kint = w_.kint[c];
      const int rp = rlo + w_.argrow[c];
      const T* col = tile + c - static_cast<ptrdiff_t>(rlo) * n;  // col[r * n] = m(u, r)
      // The contiguous run above K around the maximum; dips below K shorter than
      // min_peak_separation_px are noise inside one stripe and are bridged.
      bool edge = false;
      int re = rp;
      for (int r = rp + 1, gap = 0;; ++r) {
        if (r > rhi) {
          edge = rhi < p_.height - 1;
          break;
        }
        if (col[r * n] > kint) {
          re = r;
          gap = 0;
          if (re - rp >= o_.max_width_px) break;
        } else if (++gap >= o_.min_peak_separation_px) {
          break;
        }
      }
      int rs = rp;
      for (int r = rp - 1, gap = 0;; --r) {
        if (r < rlo) {
          edge = edge || rlo > 0;
          break;
        }
        if (col[r * n] > kint) {
          rs = r;
          gap = 0;
          if (rp - rs >= o_.max_width_px) break;
        } else if (++gap >= o_.min_peak_separation_px) {
          break;
        }
      }
      const int run = re - rs + 1;
      if (edge && run <= o_.max_width_px && margin < wide_margin_) {
        w_.retry.emplace_back(u, -1);
        continue;
      }
      // Gray centroid of the run, seed 000 eq. (7): U = sum(g_i * u_i) / sum(g_i), g the
      // filtered profile; the raw pixels of the run are checked for saturation.
      bool saturated = false;
      int run_above = 0;
      double s0 = 0.0;
      double s1 = 0.0;
      const uint8_t* raw = p_.base + sizeof(T) * u;
      if (o_.subtract_threshold) {
        const double kf = k * gmax;
        for (int r = rs; r <= re; ++r) {
          const T g = col[r * n];
          saturated |= *reinterpret_cast<const T*>(raw + r * p_.stride) >= saturation_;
          run_above += g > kint;
          const double weight = std::max(g - kf, 0.0);
          s0 += weight;
          s1 += weight * (r - rp);
        }
      } else {
        // Integer sums: exact, and the common case is worth keeping cheap.
        int64_t i0 = 0;
        int64_t i1 = 0;
        for (int r = rs; r <= re; ++r) {
          const T g = col[r * n];
          saturated |= *reinterpret_cast<const T*>(raw + r * p_.stride) >= saturation_;
          run_above += g > kint;
          i0 += g;
          i1 += static_cast<int64_t>(g) * (r - rp);
        }
        s0 = static_cast<double>(i0);
        s1 = static_cast<double>(i1);
      }
      StripeStatus status = StripeStatus::kValid;
      if (saturated) {
        status = StripeStatus::kSaturated;
      } else if (run > o_.max_width_px) {
        status = StripeStatus::kTooWide;
      } else if (w_.above[c] > run_above || w_.farmax[c] > kint) {
        // Another pixel above K in the band, at least min_peak_separation_px from the run, or
        // possibly outside the band (the bound): two peaks if it belongs to a stripe-like run.
        if (SecondStripe(u, rs, re, kint, gmax)) status = StripeStatus::kTwoPeaks;
      }
      if (status == StripeStatus::kValid && !(s0 > 0.0)) status = StripeStatus::kNone;
      const float center = status == StripeStatus::kValid ? static_cast<float>(rp + s1 / s0) : kNaN;
      int base = 0;
      if (status == StripeStatus::kValid) {
        // The local background: filtered level kBaseOffset rows beyond the run's ends (the
        // darker side, in case the other holds something else).
        const int lo = std::max(rs - kBaseOffset, 0), hi = std::min(re + kBaseOffset, p_.height - 1);
        auto m = [&](int r) { return r >= rlo && r <= rhi ? col[r * n] : ExactAt(u, r); };
        base = std::min(m(lo), m(hi));
      }
      SetResult(u, status, gmax, run, center, base);
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
  int wide_margin_ = 2;
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
                  Work<T>& work, StripeResult* result) {
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
  ColumnExtractor<T> extractor(plane, options, saturation, work, result);
  extractor.Run();
}

// Horizontal 3-tap median of pixel (u, v): removes single hot pixels from the direction estimate.
template <typename T>
int SampleAt(const Plane<T>& p, int u, int v) {
  const T* row = p.row(v);
  return Med3(row[std::max(u - 1, 0)], row[u], row[std::min(u + 1, p.width - 1)]);
}

template <typename T>
StripeDirection EstimateTyped(const Plane<T>& p) {
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
  // "Bright": above half-way between the mean level (the background, the stripe being a small
  // part of the frame) and the maximum: s > (mean + max) / 2, in integers.
  const int64_t lhs_scale = 2 * count;
  const int64_t rhs = sum + count * vmax;
  int64_t n = 0, sx = 0, sy = 0, sxx = 0, syy = 0;
  for (int v = off; v < p.height; v += step) {
    for (int u = off; u < p.width; u += step) {
      if (lhs_scale * SampleAt(p, u, v) <= rhs) continue;
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

Status StripeExtractor::Extract(const ImageView& image, StripeResult* result) {
  INSITU_RETURN_IF_ERROR(options_.Validate().Prefixed("StripeOptions"));
  if (result == nullptr) return InvalidArgument("Extract: result is null");
  INSITU_RETURN_IF_ERROR(CheckImage(image));
  StripeDirection direction = options_.direction;
  if (direction == StripeDirection::kAuto) direction = EstimateStripeDirection(image);
  result->direction = direction;
  if (image.is_8bit()) {
    ExtractTyped<uint8_t>(image, direction, options_, scratch_->w8, result);
  } else {
    ExtractTyped<uint16_t>(image, direction, options_, scratch_->w16, result);
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
  if (image.is_8bit()) return EstimateTyped(MakePlane<uint8_t>(image));
  return EstimateTyped(MakePlane<uint16_t>(image));
}

}  // namespace insitu::vision
