// Volume lines: the one-dimensional passes of the separable volume EDTs over a line of voxels, shared by the whole
// grid (core/separable/volume_edt.cc) and the band within a limit (core/separable/internal/limited_band.cc). Internal
// to core. Cells are those of core/separable/internal/lines.h; `w2` is the squared axis scale of the line's axis.
// Contract:
//   * seedLine(n, is_seed, label_of, w2, get, set): pass 1 of the seed field — cell i (get(i), set(i, cell)) becomes
//     that of the nearest seed of the line ([0, n), is_seed(i)), tagged with label_of(seed) for nearest-label cells;
//     far when the line has none. The accessors let the whole grid write rows and the band write bricks in place;
//     kStartsFar: the cells hold far before (no far is written).
//   * otherLabelLine(lab, n, known, f, d, w2, scratch): a pass of the multi-label EDT (seung-lab edt's edt::edt) over
//     voxels [0, n) of a line whose labels lab[i] are known for i in [-known.before, n + known.after). Runs of equal
//     label are the units: a voxel of label L != 0 looks only at its own run, whose ends count as voxels of another
//     label at distance 0 — a run end inside the known labels always, one at the grid's face (known.face_before /
//     face_after) when the black border is on that face (known.border_before / border_after); a run reaching past
//     the known labels is open there (its end is farther than the caller's reach). Pass 1 (f null): d[i] = w2 (distance
//     to the nearer end)^2. Passes 2 and 3: d[i] = the lower envelope of f over the run, and the ends. Label-0 voxels
//     get far (their distance, 0, is the caller's). f and d may be the same array.
// Exact: a voxel's nearest voxel of another label q is reached through the runs (step from q towards the voxel: the
// first voxel on the way is of the voxel's label, or a nearer run end), as in edt's proof. Pure; thread-safe (scratch
// is the caller's).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/separable/internal/lines.h"

namespace distband::separable_internal {

template <class C, bool kStartsFar = false, class IsSeed, class LabelOf, class Get, class Set>
inline void seedLine(int n, const IsSeed& is_seed, const LabelOf& label_of, double w2, const Get& get, const Set& set) {
  using Ops = CellOps<C>;
  int64_t last = -1;
  for (int i = 0; i < n; ++i) {
    if (is_seed(i)) last = i;
    if (kStartsFar && last < 0) continue;  // the cells hold far already
    set(i, last < 0 ? Ops::far() : Ops::make(Ops::step(w2, i - last), Ops::kTagged ? label_of(last) : 0));
  }
  last = -1;
  for (int i = n - 1; i >= 0; --i) {
    if (is_seed(i)) last = i;
    if (last < 0) continue;
    const C c = Ops::make(Ops::step(w2, last - i), Ops::kTagged ? label_of(last) : 0);
    if (Ops::less(c, get(i))) set(i, c);
  }
}

/// How far a line's labels are known beyond the voxels a pass computes, whether those ends are the grid's faces,
/// and whether the outside beyond those faces is label 0 (the black border).
struct KnownLabels {
  int before = 0, after = 0;
  bool face_before = true, face_after = true;
  bool border_before = false, border_after = false;
  /// The whole line along `axis` of a grid with the black border on `faces` (VolumeMeasure::black_border).
  static KnownLabels wholeLine(int axis, uint8_t faces) {
    KnownLabels k;
    k.border_before = (faces >> (2 * axis)) & 1;
    k.border_after = (faces >> (2 * axis + 1)) & 1;
    return k;
  }
};

/// Scratch of otherLabelLine for lines of up to n voxels.
template <class C>
struct LabelLineScratch {
  std::vector<C> f, d;
  std::vector<int> v;
  std::vector<double> z;
  // A run and its two ends: up to n + 2 positions (the band's lines are padded by the reach on the caller's side).
  explicit LabelLineScratch(int n = 0)
      : f(size_t(n) + 2), d(size_t(n) + 2), v(size_t(n) + 2), z(2 * size_t(n) + 6) {}
};

template <class C, class T>
inline void otherLabelLine(const T* lab, int n, const KnownLabels& known, const C* f, C* d, double w2,
                           LabelLineScratch<C>& s) {
  using Ops = CellOps<C>;
  using D = typename Ops::Dist;
  const T* known_lab = lab - known.before;  // known_lab[j] is voxel j - known.before
  for (int i = 0; i < n;) {
    const T label = lab[i];
    int a = i, b = i + 1;
    if (i == 0)
      for (int j = known.before; j > 0 && known_lab[j - 1] == label; --j) --a;
    while (b < n + known.after && lab[b] == label) ++b;
    const int end = std::min(b, n);
    if (label == 0) {
      std::fill(d + i, d + end, Ops::far());
      i = end;
      continue;
    }
    // A run end inside the known labels is another label; at the grid's face, the black border; else open.
    const bool left = a > -known.before || (known.face_before && known.border_before);
    const bool right = b < n + known.after || (known.face_after && known.border_after);
    if (!f) {
      for (int j = i; j < end; ++j) d[j] = Ops::make(boundaryDistance<D>(j, a, b, left, right, w2), 0);
    } else if (a == i && b == end) {
      // The run's ends as parabolas of value 0 at positions -1 and m of the run: one envelope does it all.
      const int m = end - i;
      s.f[0] = left ? Ops::make(D(0), 0) : Ops::far();
      std::copy(f + i, f + end, s.f.begin() + 1);
      s.f[size_t(m) + 1] = right ? Ops::make(D(0), 0) : Ops::far();
      parabolaEnvelope(s.f.data(), s.d.data(), m + 2, w2, s.v.data(), s.z.data());
      std::copy(s.d.begin() + 1, s.d.begin() + 1 + m, d + i);
    } else {
      // The run reaches past the computed voxels (a band's line): its ends taken afterwards.
      const int m = end - i;
      std::copy(f + i, f + end, s.f.begin());
      parabolaEnvelope(s.f.data(), s.d.data(), m, w2, s.v.data(), s.z.data());
      for (int j = i; j < end; ++j) {
        const C edge = Ops::make(boundaryDistance<D>(j, a, b, left, right, w2), 0);
        const C& env = s.d[size_t(j - i)];
        d[j] = Ops::less(edge, env) ? edge : env;
      }
    }
    i = end;
  }
}

}  // namespace distband::separable_internal
