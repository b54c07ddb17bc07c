// Separable lines: the one-dimensional steps the separable EDTs (core/separable/volume_edt.cc,
// core/separable/internal/limited_band.cc) are built of. Internal to core.
// Contract:
//   * A *cell* holds a voxel's squared distance in unit space (core/grid.h) and, for a nearest-label field, the label
//     of the seed it measures to. CellOps<C> is the one place cells are read and made:
//       - uint32_t: a cubic grid's integer squared distances (voxel units). Callers keep real values below 2^31
//         (lines are at most kMaxGridDim long: (16384)^2 * 3 < 2^30); kFarSquared marks "no seed on this line
//         (within reach)".
//       - float: an anisotropic grid's squared distances, where a step of k voxels along an axis of scale s adds
//         (s k)^2 (Grid::axisScale); +infinity is far. Sums are formed in double and rounded once per pass.
//       - Tagged<D>: either of them with the nearest seed's label; among equal distances the lower label wins, so the
//         result does not depend on the order lines are visited in.
//   * parabolaEnvelope(f, d, n, w2, v, z): d[q] = min_p f[p] + w2 (q - p)^2 over the finite f[p] (Felzenszwalb &
//     Huttenlocher's lower envelope of parabolas), carrying the winner's label; all far when none is finite. `v` and
//     `z` are scratch of n and 2 n + 2 entries. f and d must not overlap. O(n). On integer cells w2 must be 1.
//   * boundaryDistance(i, a, b, left, right, w2): the squared distance from voxel i of a label run [a, b) to the run's
//     ends, a - 1 when `left` and b when `right` (the voxels of another label beyond them, or the black border), as a
//     cell without a label; far when neither end counts.
// Pure functions; thread-safe.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

namespace distband::separable_internal {

inline constexpr uint32_t kFarSquared = std::numeric_limits<uint32_t>::max();

/// A squared distance and the label of the seed it is measured to (nearest-label fields).
template <class D>
struct Tagged {
  D d;
  uint32_t label;
  friend bool operator==(const Tagged&, const Tagged&) = default;
};

template <class C>
struct CellOps;

template <>
struct CellOps<uint32_t> {
  using Dist = uint32_t;
  static constexpr bool kTagged = false;
  static constexpr uint32_t far() { return kFarSquared; }
  static bool isFar(uint32_t c) { return c == kFarSquared; }
  static uint32_t dist(uint32_t c) { return c; }
  static uint32_t label(uint32_t) { return 0; }
  static uint32_t make(uint32_t d, uint32_t) { return d; }
  static bool less(uint32_t a, uint32_t b) { return a < b; }
  /// d + w2 k^2 (w2 is 1 on a cubic grid); far stays far.
  static uint32_t plus(uint32_t d, double, int64_t k) { return uint32_t(int64_t(d) + k * k); }
  static uint32_t step(double, int64_t k) { return uint32_t(k * k); }
};

template <>
struct CellOps<float> {
  using Dist = float;
  static constexpr bool kTagged = false;
  static constexpr float far() { return std::numeric_limits<float>::infinity(); }
  static bool isFar(float c) { return c == far(); }
  static float dist(float c) { return c; }
  static uint32_t label(float) { return 0; }
  static float make(float d, uint32_t) { return d; }
  static bool less(float a, float b) { return a < b; }
  static float plus(float d, double w2, int64_t k) { return float(double(d) + w2 * double(k) * double(k)); }
  static float step(double w2, int64_t k) { return float(w2 * double(k) * double(k)); }
};

template <class D>
struct CellOps<Tagged<D>> {
  using Dist = D;
  using Base = CellOps<D>;
  static constexpr bool kTagged = true;
  static constexpr Tagged<D> far() { return {Base::far(), 0}; }
  static bool isFar(const Tagged<D>& c) { return Base::isFar(c.d); }
  static D dist(const Tagged<D>& c) { return c.d; }
  static uint32_t label(const Tagged<D>& c) { return c.label; }
  static Tagged<D> make(D d, uint32_t label) { return {d, label}; }
  static bool less(const Tagged<D>& a, const Tagged<D>& b) { return a.d < b.d || (a.d == b.d && a.label < b.label); }
  static Tagged<D> plus(const Tagged<D>& c, double w2, int64_t k) { return {Base::plus(c.d, w2, k), c.label}; }
  static D step(double w2, int64_t k) { return Base::step(w2, k); }
};

template <class C>
inline void parabolaEnvelope(const C* f, C* d, int n, double w2, int* v, double* z) {
  using Ops = CellOps<C>;
  int k = -1;
  if constexpr (std::is_same_v<C, uint32_t>) {
    // Integers: exact, w2 = 1.
    for (int q = 0; q < n; ++q) {
      if (f[q] == kFarSquared) continue;
      const int64_t fq = int64_t(f[q]) + int64_t(q) * q;
      double s = -std::numeric_limits<double>::infinity();
      while (k >= 0) {
        const int p = v[k];
        s = double(fq - (int64_t(f[p]) + int64_t(p) * p)) / (2.0 * (q - p));
        if (s > z[k]) break;
        --k;
      }
      ++k;
      v[k] = q;
      z[k] = k == 0 ? -std::numeric_limits<double>::infinity() : s;
      z[k + 1] = std::numeric_limits<double>::infinity();
    }
  } else {
    double* const g = z + n + 1;  // each stacked parabola's f + w2 p^2
    const double inv_2w2 = 0.5 / w2;
    for (int q = 0; q < n; ++q) {
      if (Ops::isFar(f[q])) continue;
      const double fq = double(Ops::dist(f[q])) + w2 * double(q) * q;
      double s = -std::numeric_limits<double>::infinity();
      while (k >= 0) {
        s = (fq - g[k]) * inv_2w2 / double(q - v[k]);
        // Equal crossings keep the earlier parabola (and, tagged, the lower label at an exact tie below).
        if (s > z[k]) break;
        --k;
      }
      ++k;
      v[k] = q;
      g[k] = fq;
      z[k] = k == 0 ? -std::numeric_limits<double>::infinity() : s;
      z[k + 1] = std::numeric_limits<double>::infinity();
    }
  }
  if (k < 0) {
    std::fill(d, d + n, Ops::far());
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < q) ++j;
    d[q] = Ops::plus(f[v[j]], w2, int64_t(q - v[j]));
    if constexpr (Ops::kTagged) {
      // At a crossing exactly on the lattice both parabolas give the same distance: the lower label wins.
      if (j + 1 <= k && z[j + 1] == q) {
        const C other = Ops::plus(f[v[j + 1]], w2, int64_t(q - v[j + 1]));
        if (Ops::less(other, d[q])) d[q] = other;
      }
    }
  }
}

/// See the contract above. `D`: the cell's distance type.
template <class D>
inline D boundaryDistance(int64_t i, int64_t a, int64_t b, bool left, bool right, double w2) {
  using Ops = CellOps<D>;
  int64_t k = std::numeric_limits<int64_t>::max();
  if (left) k = i - (a - 1);
  if (right) k = std::min(k, b - i);
  return k == std::numeric_limits<int64_t>::max() ? Ops::far() : Ops::step(w2, k);
}

}  // namespace distband::separable_internal
