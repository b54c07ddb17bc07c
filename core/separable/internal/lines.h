// Separable lines: the one-dimensional steps the separable EDTs (core/separable/volume_edt.cc, core/separable/internal/limited_band.cc) are
// built of. Internal to core.
// Contract:
//   * Values are squared distances in voxel units as 32-bit integers; kFarSquared marks "no seed on this line (within
//     reach)". Callers keep real values below 2^31 (lines are at most kMaxGridDim long: (16384)^2 * 3 < 2^30).
//   * parabolaEnvelope(f, d, n, v, z): d[q] = min_p f[p] + (q - p)^2 over the finite f[p] (Felzenszwalb &
//     Huttenlocher's lower envelope of parabolas), all kFarSquared when none is finite. `v` and `z` are scratch of n
//     and n + 1 entries. f and d must not overlap. O(n).
// Pure functions; thread-safe.
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>

namespace distband::separable_internal {

inline constexpr uint32_t kFarSquared = std::numeric_limits<uint32_t>::max();

inline void parabolaEnvelope(const uint32_t* f, uint32_t* d, int n, int* v, double* z) {
  int k = -1;
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
  if (k < 0) {
    std::fill(d, d + n, kFarSquared);
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < q) ++j;
    const int64_t dq = int64_t(q - v[j]);
    d[q] = uint32_t(dq * dq + f[v[j]]);
  }
}

}  // namespace distband::separable_internal
