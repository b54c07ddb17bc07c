#include "core/separable/internal/limited_band.h"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <tuple>
#include <type_traits>

#include "core/brick.h"
#include "core/separable/internal/volume_lines.h"

namespace distband::separable_internal {
namespace {

constexpr int kStride[3] = {64, 8, 1};  // brickOffset's step along x, y, z
constexpr int kWindowReach = 16;        // see cellsWithin
constexpr int kMultiLabelWindowReach = 2;  // see cellsWithin
constexpr int kGatherAhead = 8;            // positions a run's label gather prefetches ahead

/// Voxels along an axis of squared scale `w2` within sqrt(cut2) units.
int reachVoxels(double cut2, double w2) {
  return int(std::min(std::floor(std::sqrt(cut2) / std::sqrt(w2)), double(kMaxGridDim)));
}

bool hasZeroByte(uint64_t w) { return ((w - 0x0101010101010101ull) & ~w & 0x8080808080808080ull) != 0; }

int along(const Coord& c, int axis) { return axis == 0 ? c.x : axis == 1 ? c.y : c.z; }

/// "Far" inside the window minimum: far plus reach^2 can neither wrap nor pass for a value within the cut.
template <class C>
C windowFar() {
  if constexpr (std::is_same_v<C, uint32_t>) return uint32_t(1) << 30;
  else if constexpr (std::is_same_v<C, Tagged<uint32_t>>) return {uint32_t(1) << 30, 0};
  else return CellOps<C>::far();
}

/// Bricks of one pass, in runs of consecutive bricks along the pass's axis. `slot` indexes the pool; a brick whose
/// slot holds no values yet (the growth added it) starts all far.
struct Runs {
  struct Run {
    int other[2];  // the run's brick coordinates on the two other axes (ascending axis order)
    int lo, hi;    // brick range along the axis, inclusive
    size_t first;  // its first brick in `slot`
  };
  std::vector<Run> runs;
  std::vector<uint32_t> slot;
  std::vector<uint8_t> seed;  // the brick was listed, not added by the growth (pass 1: it holds a boundary)
};

/// Where bricks live: carved from slabs, one open slab per thread. First touches of fresh memory are a large part of
/// a pass's cost (page faults are slow on virtual machines): 2 MiB slabs ask for transparent huge pages, and a brick
/// is only allocated once it holds a value.
template <class C>
class BrickArena {
 public:
  static constexpr size_t kBrickBytes = kBrickVoxels * sizeof(C);
  // Each thread's slabs double from 64 KiB to 2 MiB, so a small band does not hold megabytes per thread (the space a
  // thread's open slab leaves unused is at most what it already holds, plus 64 KiB), and a large one gets huge pages.
  static constexpr size_t kFirstSlabBytes = size_t(64) << 10, kHugeSlabBytes = size_t(2) << 20;
  C* allocate() {
    Local& l = local_.local();
    if (l.left == 0) {
      const size_t bytes = l.slab_bytes;
      void* p = std::aligned_alloc(bytes, bytes);
      if (!p) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
      if (bytes == kHugeSlabBytes) ::madvise(p, bytes, MADV_HUGEPAGE);  // advice only: without it, 4 KiB pages
#endif
      l.slabs.emplace_back(p, std::free);
      l.next = static_cast<C*>(p);
      l.left = bytes / kBrickBytes;
      l.slab_bytes = std::min(2 * bytes, kHugeSlabBytes);
    }
    --l.left;
    C* b = l.next;
    l.next += kBrickVoxels;
    return b;
  }
  /// Hands the slabs over (the arena is left empty).
  void release(std::vector<std::shared_ptr<void>>* to) {
    for (Local& l : local_) {
      for (auto& s : l.slabs) to->push_back(std::move(s));
      l = Local{};
    }
  }

 private:
  struct Local {
    std::vector<std::shared_ptr<void>> slabs;
    C* next = nullptr;
    size_t left = 0;
    size_t slab_bytes = kFirstSlabBytes;
  };
  tbb::enumerable_thread_specific<Local> local_;
};

/// Groups `bricks` (their coordinates and pool slots; slot kNoSlot: not allocated yet) along `axis`, dilated by
/// `reach` bricks along it within [clip_lo, clip_hi] (the bricks lie there), into runs. Bricks the dilation adds get
/// fresh slots at the end of the pool.
constexpr uint32_t kNoSlot = ~uint32_t(0);
struct BrickRef {
  int c[3];
  uint32_t slot;
};
template <class Pool>
Runs buildRuns(std::vector<BrickRef>& bricks, int axis, int reach, const Coord& brick_dims, Pool& pool, int clip_lo = 0,
               int clip_hi = std::numeric_limits<int>::max()) {
  const int o0 = axis == 0 ? 1 : 0, o1 = axis == 2 ? 1 : 2;  // the other two axes, ascending
  tbb::parallel_sort(bricks.begin(), bricks.end(), [&](const BrickRef& a, const BrickRef& b) {
    return std::tie(a.c[o1], a.c[o0], a.c[axis]) < std::tie(b.c[o1], b.c[o0], b.c[axis]);
  });
  Runs r;
  const int n_axis = along(brick_dims, axis);
  for (size_t i = 0; i < bricks.size();) {
    size_t j = i;
    while (j < bricks.size() && bricks[j].c[o0] == bricks[i].c[o0] && bricks[j].c[o1] == bricks[i].c[o1]) ++j;
    // Bricks i..j-1 share a line of bricks; merge their dilated intervals.
    size_t k = i;
    while (k < j) {
      const int top = std::min(n_axis - 1, clip_hi);
      const int lo = std::max(std::max(0, clip_lo), bricks[k].c[axis] - reach);
      int hi = std::min(top, bricks[k].c[axis] + reach);
      size_t m = k + 1;
      while (m < j && bricks[m].c[axis] - reach <= hi + 1) hi = std::min(top, bricks[m++].c[axis] + reach);
      Runs::Run run{{bricks[i].c[o0], bricks[i].c[o1]}, lo, hi, r.slot.size()};
      size_t e = k;  // walks the existing bricks k..m-1, which lie inside [lo, hi] in order
      for (int a = lo; a <= hi; ++a) {
        const bool existing = e < m && bricks[e].c[axis] == a;
        uint32_t s = existing ? bricks[e].slot : kNoSlot;
        r.seed.push_back(existing);
        if (existing) ++e;
        if (s == kNoSlot) {
          s = uint32_t(pool.size());
          pool.push_back(nullptr);
        }
        r.slot.push_back(s);
      }
      r.runs.push_back(run);
      k = m;
    }
    i = j;
  }
  return r;
}

/// The pool slots still allocated, as bricks (unordered).
template <class Pool>
std::vector<BrickRef> liveBricks(const Runs& r, int axis, const Pool& pool) {
  const int o0 = axis == 0 ? 1 : 0, o1 = axis == 2 ? 1 : 2;
  std::vector<BrickRef> out;
  for (const Runs::Run& run : r.runs)
    for (int a = run.lo; a <= run.hi; ++a) {
      const uint32_t s = r.slot[run.first + size_t(a - run.lo)];
      if (!pool[s]) continue;
      BrickRef b{};
      b.c[axis] = a;
      b.c[o0] = run.other[0];
      b.c[o1] = run.other[1];
      b.slot = s;
      out.push_back(b);
    }
  return out;
}

/// Per-thread scratch of a line pass: a line's input and output, its labels (with the reach beyond both ends), the
/// envelope's stacks, and eight lines side by side padded by the reach both ways (the window minimum).
template <class C, class T>
struct LineScratch {
  std::vector<C> f, d;
  std::vector<T> labels;
  LabelLineScratch<C> runs;
  std::vector<int> v;
  std::vector<double> z;
  std::vector<std::array<C, kBrickSize>> lanes;
  // Multi-label window: a run's labels, its 8 x 8 lines at each position (gathered once per run: a line along y or z
  // reads a cache line per voxel), and one bundle's eight lines.
  std::vector<T> block;
  std::vector<std::array<T, kBrickSize>> label_lanes;
  std::vector<std::array<C, kBrickSize>> run_lo, run_hi;
  LineScratch(int n, int reach)
      : f(size_t(n)),
        d(size_t(n)),
        labels(size_t(n) + 2 * size_t(reach)),
        runs(n),
        v(size_t(n)),
        z(2 * size_t(n) + 2),
        lanes(size_t(n) + 2 * size_t(reach)) {}
};

/// Runs `lines(run index, u, base, w_end, length, brick values, scratch)` for every eight lines of voxels of every run
/// that share their local coordinate u on the first other axis: line w (< w_end, inside the grid) is voxel offset
/// base + w * kStride[second other axis] + i * kStride[axis] of brick i / 8 at position i < length. In parallel over
/// runs. A run's fresh bricks are worked on in scratch and allocated from `arena` only if they got a value. False
/// when interrupted.
template <class C, class T, class Lines>
bool forEachLines(const Runs& r, int axis, const Coord& dims, int reach_voxels, std::vector<C*>& pool,
                  BrickArena<C>& arena, const Interrupter* interrupter, const Lines& lines) {
  using Ops = CellOps<C>;
  const int o0 = axis == 0 ? 1 : 0, o1 = axis == 2 ? 1 : 2;
  const int n[3] = {dims.x, dims.y, dims.z};
  // Scratch per thread, not per range: ranges are a few runs each, and fresh buffers cost more than the runs' lines.
  tbb::enumerable_thread_specific<LineScratch<C, T>> scratches(n[axis], reach_voxels);
  tbb::enumerable_thread_specific<std::vector<C*>> brick_lists;
  tbb::enumerable_thread_specific<std::vector<C>> fresh_scratch;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, r.runs.size(), 4), [&](const tbb::blocked_range<size_t>& range) {
    std::vector<C*>& bricks = brick_lists.local();
    std::vector<C>& fresh = fresh_scratch.local();
    LineScratch<C, T>& scratch = scratches.local();
    for (size_t ri = range.begin(); ri != range.end(); ++ri) {
      if (isInterrupted(interrupter)) return;
      const Runs::Run& run = r.runs[ri];
      const size_t count = size_t(run.hi - run.lo + 1);
      bricks.resize(count);
      if (fresh.size() < count * kBrickVoxels) fresh.resize(count * kBrickVoxels);
      // Each slot belongs to one run: a null one is a fresh brick (no other run can have filled it meanwhile).
      for (size_t i = 0; i < count; ++i) {
        bricks[i] = pool[r.slot[run.first + i]];
        if (!bricks[i]) {
          bricks[i] = fresh.data() + i * kBrickVoxels;
          std::fill(bricks[i], bricks[i] + kBrickVoxels, Ops::far());
        }
      }
      const int length = std::min(int(count) * kBrickSize, n[axis] - run.lo * kBrickSize);
      const int u_end = std::min(kBrickSize, n[o0] - run.other[0] * kBrickSize);
      const int w_end = std::min(kBrickSize, n[o1] - run.other[1] * kBrickSize);
      for (int u = 0; u < u_end; ++u) lines(ri, u, u * kStride[o0], w_end, length, bricks.data(), scratch);
      for (size_t i = 0; i < count; ++i) {
        C*& slot = pool[r.slot[run.first + i]];
        const C* v = bricks[i];
        if (slot || std::all_of(v, v + kBrickVoxels, [](const C& x) { return Ops::isFar(x); })) continue;
        slot = arena.allocate();
        std::copy(v, v + kBrickVoxels, slot);
      }
    }
  });
  return !isInterrupted(interrupter);
}

// Where what a target measures to can lie: seed field, the bricks holding a seed's boundary (mixed ones, and
// all-seed ones beside a brick that is not all seeds); multi-label, the bricks holding a label boundary (mixed ones,
// uniform ones beside a brick that is not uniform of the same label, and with a black border those at the faces).
bool isBoundaryBrick(const Grid& grid, const BrickClasses& classes, const BandMeasure& measure, int bx, int by,
                     int bz) {
  const Coord bd = grid.brickDims();
  const bool multi = measure.multi_label;
  const uint8_t all_seeds = measure.seeds_nonzero ? kAllMaskVoxels : kNoMaskVoxel;
  const uint8_t no_seeds = measure.seeds_nonzero ? kNoMaskVoxel : kAllMaskVoxels;
  const size_t b = size_t(grid.brickIndex({bx, by, bz}));
  const int c[3] = {bx, by, bz};
  if (multi) {
    if (!classes.uniform[b]) return true;
    for (int a = 0; a < 3; ++a)
      for (int s : {-1, 1}) {
        int nc[3] = {c[0], c[1], c[2]};
        nc[a] += s;
        if (nc[a] < 0 || nc[a] >= along(bd, a)) {
          if ((measure.black_border >> (2 * a + (s > 0))) & 1) return true;
          continue;
        }
        const size_t n = size_t(grid.brickIndex({nc[0], nc[1], nc[2]}));
        if (!classes.uniform[n] || classes.label[n] != classes.label[b]) return true;
      }
    return false;
  }
  const uint8_t kind = classes.mask[b];
  bool boundary = kind == kSomeMaskVoxels;
  if (kind == all_seeds)
    for (int a = 0; a < 3 && !boundary; ++a)
      for (int s : {-1, 1}) {
        int nc[3] = {c[0], c[1], c[2]};
        nc[a] += s;
        if (nc[a] < 0 || nc[a] >= along(bd, a)) continue;
        if (classes.mask[size_t(grid.brickIndex({nc[0], nc[1], nc[2]}))] != all_seeds) boundary = true;
      }
  return boundary && kind != no_seeds;
}

}  // namespace

template <class C>
const C* CellBricks<C>::find(uint64_t key) const {
  const auto it = std::lower_bound(keys.begin(), keys.end(), key);
  return it != keys.end() && *it == key ? values[size_t(it - keys.begin())] : nullptr;
}

template <class T>
BrickClasses classifyBricks(const Grid& grid, const T* labels, bool multi_label, const Interrupter* interrupter) {
  const Coord dims = grid.dims(), bd = grid.brickDims();
  BrickClasses out;
  out.mask.assign(size_t(grid.brickCount()), 0);
  if (multi_label) {
    out.uniform.assign(out.mask.size(), 0);
    out.label.assign(out.mask.size(), 0);
  }
  // One line of bricks (by, bz) at a time: its 64 voxel rows are read front to back (uint8: a word per brick row).
  tbb::parallel_for(tbb::blocked_range<size_t>(0, size_t(bd.y) * bd.z, 4), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<uint8_t> any(size_t(bd.x)), all(size_t(bd.x)), same(multi_label ? size_t(bd.x) : 0);
    std::vector<T> first(multi_label ? size_t(bd.x) : 0);
    for (size_t line = r.begin(); line != r.end(); ++line) {
      if (isInterrupted(interrupter)) return;
      const int by = int(line % size_t(bd.y)), bz = int(line / size_t(bd.y));
      std::fill(any.begin(), any.end(), 0);
      std::fill(all.begin(), all.end(), 1);
      std::fill(same.begin(), same.end(), 1);
      const T* corner = labels + (size_t(bz) * kBrickSize * dims.y + size_t(by) * kBrickSize) * dims.x;
      for (size_t bx = 0; bx < first.size(); ++bx) first[bx] = corner[bx * kBrickSize];
      for (int z = bz * kBrickSize; z < std::min(dims.z, (bz + 1) * kBrickSize); ++z)
        for (int y = by * kBrickSize; y < std::min(dims.y, (by + 1) * kBrickSize); ++y) {
          const T* row = labels + (size_t(z) * dims.y + y) * dims.x;
          int bx = 0;
          if constexpr (std::is_same_v<T, uint8_t>) {
            if (!multi_label)
              for (; (bx + 1) * kBrickSize <= dims.x; ++bx) {
                uint64_t word;
                std::memcpy(&word, row + bx * kBrickSize, sizeof word);
                any[size_t(bx)] |= word != 0;
                all[size_t(bx)] &= !hasZeroByte(word);
              }
          }
          if (multi_label)  // most brick rows hold one label: compare them whole, classify the rest voxel by voxel
            for (; (bx + 1) * kBrickSize <= dims.x; ++bx) {
              const T* v = row + bx * kBrickSize;
              const T f = first[size_t(bx)];
              bool one = true;
              for (int k = 0; k < kBrickSize; ++k) one &= v[k] == f;
              if (one) {
                any[size_t(bx)] |= f != 0;
                all[size_t(bx)] &= f != 0;
                continue;
              }
              same[size_t(bx)] = 0;
              for (int k = 0; k < kBrickSize; ++k) {
                any[size_t(bx)] |= v[k] != 0;
                all[size_t(bx)] &= v[k] != 0;
              }
            }
          for (int x = bx * kBrickSize; x < dims.x; ++x) {
            const size_t b = size_t(x >> kBrickLog2);
            any[b] |= row[x] != 0;
            all[b] &= row[x] != 0;
            if (multi_label) same[b] &= row[x] == first[b];
          }
        }
      const size_t at = line * size_t(bd.x);
      for (size_t bx = 0; bx < size_t(bd.x); ++bx) {
        out.mask[at + bx] = !any[bx] ? kNoMaskVoxel : all[bx] ? kAllMaskVoxels : kSomeMaskVoxels;
        if (multi_label) {
          out.uniform[at + bx] = same[bx];
          out.label[at + bx] = uint32_t(first[bx]);
        }
      }
    }
  });
  return out;
}

template <class C, class T>
bool cellsWithin(const Grid& grid, const T* labels, const BrickClasses& classes, const BandMeasure& measure,
                 typename CellOps<C>::Dist cut2, const double w2[3], const Interrupter* interrupter, CellBricks<C>* out,
                 BrickLayers layers) {
  using Ops = CellOps<C>;
  const Coord dims = grid.dims(), bd = grid.brickDims();
  const bool multi = measure.multi_label;
  // The reach along each axis: voxels (of that axis) within sqrt(cut2) units.
  int reach_voxels[3], reach_bricks[3];
  for (int a = 0; a < 3; ++a) {
    reach_voxels[a] = reachVoxels(double(cut2), w2[a]);
    reach_bricks[a] = reachLayers(double(cut2), w2[a]);
  }
  // The layers computed, and the layers their targets reach (what they measure to lies there).
  const int out_lo = std::max(layers.lo, 0), out_hi = std::min(layers.hi, bd.z);
  if (out_lo >= out_hi) return true;
  const int read_lo = std::max(out_lo - reach_bricks[2], 0), read_hi = std::min(out_hi + reach_bricks[2], bd.z);
  std::vector<std::vector<BrickRef>> per_slab(size_t(bd.z));
  tbb::parallel_for(read_lo, read_hi, [&](int bz) {
    if (isInterrupted(interrupter)) return;
    for (int by = 0; by < bd.y; ++by)
      for (int bx = 0; bx < bd.x; ++bx)
        if (isBoundaryBrick(grid, classes, measure, bx, by, bz))
          per_slab[size_t(bz)].push_back({{bx, by, bz}, kNoSlot});
  });
  if (isInterrupted(interrupter)) return false;
  std::vector<BrickRef> bricks;
  for (auto& slab : per_slab) bricks.insert(bricks.end(), slab.begin(), slab.end());
  std::vector<std::vector<BrickRef>>().swap(per_slab);
  // Multi-label: a run end along y or z is a label boundary of its own, known from the labels and not from the
  // previous pass's values, so the boundary bricks join every pass (a boundary parallel to x leaves pass 1 nothing).
  const std::vector<BrickRef> boundary = multi ? bricks : std::vector<BrickRef>();
  auto withBoundary = [&](std::vector<BrickRef> live) {
    if (!multi) return live;
    live.insert(live.end(), boundary.begin(), boundary.end());  // boundary entries have no slot: after live ones
    std::stable_sort(live.begin(), live.end(), [](const BrickRef& a, const BrickRef& b) {
      return std::tie(a.c[2], a.c[1], a.c[0]) < std::tie(b.c[2], b.c[1], b.c[0]);
    });
    live.erase(std::unique(live.begin(), live.end(),
                           [](const BrickRef& a, const BrickRef& b) {
                             return a.c[0] == b.c[0] && a.c[1] == b.c[1] && a.c[2] == b.c[2];
                           }),
               live.end());
    return live;
  };

  const auto keep = [cut2](const C& c) { return Ops::dist(c) <= cut2 ? c : Ops::far(); };
  std::vector<C*> pool;
  BrickArena<C> arena;
  const int N[3] = {dims.x, dims.y, dims.z};
  // The labels a multi-label line pass reads: its voxels and up to the reach beyond each end, within the grid.
  auto knownLabels = [&](int axis, int start, int length) {
    KnownLabels k;
    k.before = std::min(start, reach_voxels[axis]);
    k.after = std::min(N[axis] - (start + length), reach_voxels[axis]);
    k.face_before = start - k.before == 0;
    k.face_after = start + length + k.after == N[axis];
    k.border_before = (measure.black_border >> (2 * axis)) & 1;
    k.border_after = (measure.black_border >> (2 * axis + 1)) & 1;
    return k;
  };
  // Pass 1, along x: each voxel's squared distance to the nearest seed of its row (within the boundary bricks), or,
  // multi-label, to the nearest end of its label run.
  Runs runs = buildRuns(bricks, 0, reach_bricks[0], bd, pool);
  const bool ok1 = forEachLines<C, T>(
      runs, 0, dims, reach_voxels[0], pool, arena, interrupter,
      [&](size_t ri, int u, int base, int w_end, int length, C* const* values, LineScratch<C, T>& s) {
        const Runs::Run& run = runs.runs[ri];
        const uint8_t* seed_brick = runs.seed.data() + run.first;
        const int x0 = run.lo * kBrickSize;
        for (int w = 0; w < w_end; ++w) {
          const size_t y = size_t(run.other[0]) * kBrickSize + size_t(u),
                       z = size_t(run.other[1]) * kBrickSize + size_t(w);
          const T* row = labels + (z * size_t(dims.y) + y) * size_t(dims.x) + size_t(x0);
          const int line = base + w * kStride[2];
          auto at = [&](int i) -> C& {  // i >= 0: unsigned, so / and % are shifts
            return values[unsigned(i) / kBrickSize][line + (unsigned(i) % kBrickSize) * kStride[0]];
          };
          if (multi) {
            otherLabelLine<C, T>(row, length, knownLabels(0, x0, length), nullptr, s.d.data(), w2[0], s.runs);
            for (int i = 0; i < length; ++i) at(i) = keep(s.d[size_t(i)]);
          } else {
            const bool nonzero = measure.seeds_nonzero;
            seedLine<C, true>(  // pass 1's bricks are fresh: all far
                length, [&](int i) { return seed_brick[i / kBrickSize] && (row[i] != 0) == nonzero; },
                [&](int i) { return uint32_t(row[i]); }, w2[0], [&](int i) -> const C& { return at(i); },
                [&](int i, const C& c) { at(i) = keep(c); });
          }
        }
      });
  if (!ok1) return false;
  // Passes 2 and 3, along y and z: the lower envelope of the previous pass's parabolas on each line (multi-label: on
  // each label run of it).
  for (int axis : {1, 2}) {
    bricks = withBoundary(liveBricks(runs, axis == 1 ? 0 : 1, pool));
    // Along z the runs stop at the layers read: the targets beyond are not computed.
    runs = axis == 2 ? buildRuns(bricks, axis, reach_bricks[axis], bd, pool, read_lo, read_hi - 1)
                     : buildRuns(bricks, axis, reach_bricks[axis], bd, pool);
    const int o1 = axis == 2 ? 1 : 2;  // the second other axis: the lanes of a bundle
    const int reach = reach_voxels[axis];
    const double wa = w2[axis];
    // The window's eight lines side by side (s.lanes, from index reach): the cells of the bundle, padded by `reach` far
    // rows at each end. Returns whether any cell is not far. Generic for the reason multiLabelWindow is.
    auto loadLanes = [&](auto& s, int w_end, int length, const auto& at) {
      auto* lane = s.lanes.data() + reach;
      bool any = false;
      for (int i = -reach; i < length + reach; ++i) lane[i].fill(windowFar<C>());
      for (int i = 0; i < length; ++i)
        for (int w = 0; w < w_end; ++w) {
          const C f = at(i, w);
          any |= !Ops::isFar(f);
          if (!Ops::isFar(f)) lane[i][size_t(w)] = f;
        }
      return any;
    };
    // A multi-label run's labels, read once for its 8 x 8 lines (a line along y or z alone reads a cache line per
    // voxel): block[(i + reach) * 64 + w * 8 + u] is the label of line (u, w) at position i of the run, for i in
    // [-known.before, length + known.after). Called for u = 0, before the run's lines.
    auto gatherRunLabels = [&](const Runs::Run& run, const KnownLabels& known, int w_end, int length,
                               LineScratch<C, T>& s) {
      const int start = run.lo * kBrickSize;
      const int x0 = run.other[0] * kBrickSize;  // x: the first other axis of both passes
      const int u_end = std::min(kBrickSize, dims.x - x0);
      s.block.resize((size_t(length) + 2 * size_t(reach)) * kBrickSize * kBrickSize);
      const int64_t step = axis == 1 ? int64_t(dims.x) : int64_t(dims.x) * dims.y;
      const int64_t w_step = axis == 1 ? int64_t(dims.x) * dims.y : int64_t(dims.x);
      const T* corner = labels + x0 + int64_t(run.other[1]) * kBrickSize * w_step;
      const int end = length + known.after;
      for (int i = -known.before; i < end; ++i) {
        const T* p = corner + int64_t(start + i) * step;
        // Each row is a cache line of its own, a slice or a row apart: no hardware prefetcher follows them.
        if (i + kGatherAhead < end)
          for (int w = 0; w < w_end; ++w) __builtin_prefetch(p + kGatherAhead * step + w * w_step);
        T* to = s.block.data() + size_t(i + reach) * kBrickSize * kBrickSize;
        for (int w = 0; w < w_end; ++w)
          if (u_end == kBrickSize)  // a constant size: no call
            std::memcpy(to + w * kBrickSize, p + w * w_step, kBrickSize * sizeof(T));
          else
            std::memcpy(to + w * kBrickSize, p + w * w_step, size_t(u_end) * sizeof(T));
      }
    };
    // A step of k voxels (k <= reach): with float cells the window adds in float, which equals the envelope's sum
    // in double rounded once when every step is a float and no two values differ by more than 2^28 (a sum of two
    // floats is then exact in double); otherwise the envelope runs.
    using Dist = typename Ops::Dist;
    std::array<Dist, kMultiLabelWindowReach + 1> steps{};
    bool float_sums_exact = true;
    for (int k = 1; k <= std::min(reach, kMultiLabelWindowReach); ++k) {
      steps[size_t(k)] = Ops::step(wa, k);
      float_sums_exact &= double(steps[size_t(k)]) == wa * k * k;
    }
    float_sums_exact &= double(cut2) < std::ldexp(std::min({w2[0], w2[1], w2[2]}), 28);
    // The window minimum takes 2 reach + 1 candidates a voxel, eight lines at once: cheaper than the envelope's
    // per-voxel bookkeeping up to ~16 voxels (multi-label: up to 2, each candidate also checks the label run).
    const bool window = multi ? reach <= kMultiLabelWindowReach && (std::is_integral_v<Dist> || float_sums_exact)
                              : reach <= kWindowReach;
    // The multi-label pass as a window minimum over eight lines (the bundle of local coordinate u): a voxel of label
    // L takes f + w2 k^2 from the voxels k <= reach away while its label run goes on, and w2 k^2 from the first voxel
    // of another label (a run end: distance 0), as the envelope over the run and its ends would (otherLabelLine).
    // Beyond the grid's face the outside is label 0 with the black border there, else the line's edge label with
    // nothing measured (no run end). Label-0 voxels get far (the caller's 0).
    // Generic (`s` and `at`), so that cells with labels (which never take this path) do not instantiate it. Only up
    // to a reach of 2: its candidates cost more than the envelope beyond (pass 2 of 100 labels at a reach of 5).
    auto multiLabelWindow = [&](const Runs::Run& run, int u, int w_end, int length, auto& s, const auto& at) {
      using V = typename std::remove_cvref_t<decltype(s.lanes)>::value_type::value_type;  // C
      const int start = run.lo * kBrickSize;
      const KnownLabels known = knownLabels(axis, start, length);
      const size_t span = size_t(length) + 2 * size_t(reach);
      if (u == 0) gatherRunLabels(run, known, w_end, length, s);
      s.label_lanes.resize(span);
      auto* lab = s.label_lanes.data() + reach;
      auto* lane = s.lanes.data() + reach;
      for (int i = -known.before; i < length + known.after; ++i) {
        const T* from = s.block.data() + size_t(i + reach) * kBrickSize * kBrickSize + u;
        for (int w = 0; w < kBrickSize; ++w) lab[i][size_t(w)] = w < w_end ? from[w * kBrickSize] : T(0);
      }
      // Outside the grid (within the reach): label 0 behind a black border, else the edge's label (the run goes on).
      const bool border_before = known.face_before && known.border_before,
                 border_after = known.face_after && known.border_after;
      for (int i = -reach; i < -known.before; ++i)
        for (int w = 0; w < kBrickSize; ++w) lab[i][size_t(w)] = border_before ? T(0) : lab[-known.before][size_t(w)];
      for (int i = length + known.after; i < length + reach; ++i)
        for (int w = 0; w < kBrickSize; ++w)
          lab[i][size_t(w)] = border_after ? T(0) : lab[length + known.after - 1][size_t(w)];
      const V far = windowFar<V>();
      loadLanes(s, w_end, length, at);
      // How far each voxel's label run goes on below and above, capped at the reach: a run end within the reach is
      // the first voxel of another label, one step past it.
      s.run_lo.resize(span);
      s.run_hi.resize(span);
      auto* lo = s.run_lo.data() + reach;
      auto* hi = s.run_hi.data() + reach;
      const V cap = V(reach);
      lo[-reach].fill(cap);
      for (int i = -reach + 1; i < length; ++i)
        for (size_t w = 0; w < kBrickSize; ++w)
          lo[i][w] = lab[i - 1][w] == lab[i][w] ? std::min(V(lo[i - 1][w] + V(1)), cap) : V(0);
      hi[length + reach - 1].fill(cap);
      for (int i = length + reach - 2; i >= 0; --i)
        for (size_t w = 0; w < kBrickSize; ++w)
          hi[i][w] = lab[i + 1][w] == lab[i][w] ? std::min(V(hi[i + 1][w] + V(1)), cap) : V(0);
      for (int i = 0; i < length; ++i) {
        std::array<V, kBrickSize> m = lane[i];
        for (int k = 1; k <= reach; ++k) {
          const V kc = V(k), end = steps[size_t(k)];
          const auto& flo = lane[i - k];
          const auto& fhi = lane[i + k];
          for (size_t w = 0; w < kBrickSize; ++w) {
            const V via_lo = kc <= lo[i][w] ? V(flo[w] + end) : kc == lo[i][w] + V(1) ? end : far;
            const V via_hi = kc <= hi[i][w] ? V(fhi[w] + end) : kc == hi[i][w] + V(1) ? end : far;
            m[w] = std::min(m[w], std::min(via_lo, via_hi));
          }
        }
        const std::array<T, kBrickSize>& own = lab[i];
        for (int w = 0; w < w_end; ++w) at(i, w) = own[size_t(w)] == 0 ? Ops::far() : keep(m[size_t(w)]);
      }
    };
    const bool ok = forEachLines<C, T>(
        runs, axis, dims, reach, pool, arena, interrupter,
        [&](size_t ri, int u, int base, int w_end, int length, C* const* values, LineScratch<C, T>& s) {
          auto at = [&](int i, int w) -> C& {  // i >= 0: unsigned, so / and % are shifts
            return values[unsigned(i) / kBrickSize]
                         [base + w * kStride[o1] + (unsigned(i) % kBrickSize) * kStride[axis]];
          };
          if constexpr (!Ops::kTagged) {  // nearest labels are the seed field's only
            if (window && multi) {
              multiLabelWindow(runs.runs[ri], u, w_end, length, s, at);
              return;
            }
          }
          if (window) {
            auto* lane = s.lanes.data() + reach;
            if (!loadLanes(s, w_end, length, at)) return;
            for (int i = 0; i < length; ++i) {
              std::array<C, kBrickSize> m = lane[i];
              for (int k = 1; k <= reach; ++k) {
                const auto& lo = lane[i - k];
                const auto& hi = lane[i + k];
                if constexpr (std::is_same_v<C, uint32_t>) {
                  const uint32_t kk = uint32_t(k * k);
                  for (size_t w = 0; w < kBrickSize; ++w) m[w] = std::min(m[w], std::min(lo[w], hi[w]) + kk);
                } else {
                  for (size_t w = 0; w < kBrickSize; ++w) {
                    const C c = Ops::plus(Ops::less(hi[w], lo[w]) ? hi[w] : lo[w], wa, k);
                    if (Ops::less(c, m[w])) m[w] = c;
                  }
                }
              }
              for (int w = 0; w < w_end; ++w) at(i, w) = keep(m[size_t(w)]);
            }
            return;
          }
          const Runs::Run& run = runs.runs[ri];
          const int start = run.lo * kBrickSize;
          const KnownLabels known = multi ? knownLabels(axis, start, length) : KnownLabels{};
          if (multi && u == 0) gatherRunLabels(run, known, w_end, length, s);
          // Line w's cells, brick by brick: fn(i, cell) for i < length.
          auto forLine = [&](int w, const auto& fn) {
            const int step = kStride[axis];
            for (int b = 0, i = 0; i < length; ++b) {
              C* p = values[b] + base + w * kStride[o1];
              for (const int e = std::min(length, i + kBrickSize); i < e; ++i, p += step) fn(i, *p);
            }
          };
          for (int w = 0; w < w_end; ++w) {
            bool any = false;
            forLine(w, [&](int i, const C& c) {
              s.f[size_t(i)] = c;
              any |= !Ops::isFar(c);
            });
            if (!any && !multi) continue;  // multi-label: the run ends along this line count without any value
            if (multi) {
              // The line's labels, `known` beyond its ends, from the run's block.
              const T* p = s.block.data() + size_t(reach - known.before) * kBrickSize * kBrickSize + w * kBrickSize + u;
              const int total = known.before + length + known.after;
              for (int i = 0; i < total; ++i) s.labels[size_t(i)] = p[size_t(i) * kBrickSize * kBrickSize];
              otherLabelLine<C, T>(s.labels.data() + known.before, length, known, s.f.data(), s.d.data(), wa, s.runs);
            } else {
              parabolaEnvelope(s.f.data(), s.d.data(), length, wa, s.v.data(), s.z.data());
            }
            forLine(w, [&](int i, C& c) { c = keep(s.d[size_t(i)]); });
          }
        });
    if (!ok) return false;
  }
  bricks = liveBricks(runs, 2, pool);
  bricks.erase(std::remove_if(bricks.begin(), bricks.end(),
                              [&](const BrickRef& b) { return b.c[2] < out_lo || b.c[2] >= out_hi; }),
               bricks.end());
  std::vector<std::pair<uint64_t, uint32_t>> order(bricks.size());
  for (size_t i = 0; i < bricks.size(); ++i) {
    const int* c = bricks[i].c;
    order[i] = {uint64_t(grid.brickIndex({c[0], c[1], c[2]})), bricks[i].slot};
  }
  tbb::parallel_sort(order.begin(), order.end());
  out->keys.resize(order.size());
  out->values.resize(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    out->keys[i] = order[i].first;
    out->values[i] = pool[order[i].second];
  }
  arena.release(&out->storage);
  return true;
}

std::vector<int64_t> boundaryBricksPerLayer(const Grid& grid, const BrickClasses& classes, const BandMeasure& measure) {
  const Coord bd = grid.brickDims();
  std::vector<int64_t> count(size_t(bd.z), 0);
  tbb::parallel_for(0, bd.z, [&](int bz) {
    for (int by = 0; by < bd.y; ++by)
      for (int bx = 0; bx < bd.x; ++bx) count[size_t(bz)] += isBoundaryBrick(grid, classes, measure, bx, by, bz);
  });
  return count;
}

int reachLayers(double cut2, double w2z) { return (reachVoxels(cut2, w2z) + kBrickSize - 1) / kBrickSize; }

// The cells and label types the separable volume EDT runs with.
#define DISTBAND_CELLS_WITHIN(C, T)                                                                               \
  template bool cellsWithin<C, T>(const Grid&, const T*, const BrickClasses&, const BandMeasure&,                 \
                                  typename CellOps<C>::Dist, const double[3], const Interrupter*, CellBricks<C>*, \
                                  BrickLayers);
#define DISTBAND_FOR_LABELS(C)      \
  DISTBAND_CELLS_WITHIN(C, uint8_t)  \
  DISTBAND_CELLS_WITHIN(C, uint16_t) \
  DISTBAND_CELLS_WITHIN(C, uint32_t) \
  template struct CellBricks<C>;
DISTBAND_FOR_LABELS(uint32_t)
DISTBAND_FOR_LABELS(float)
DISTBAND_FOR_LABELS(Tagged<uint32_t>)
DISTBAND_FOR_LABELS(Tagged<float>)
#undef DISTBAND_FOR_LABELS
#undef DISTBAND_CELLS_WITHIN
template BrickClasses classifyBricks<uint8_t>(const Grid&, const uint8_t*, bool, const Interrupter*);
template BrickClasses classifyBricks<uint16_t>(const Grid&, const uint16_t*, bool, const Interrupter*);
template BrickClasses classifyBricks<uint32_t>(const Grid&, const uint32_t*, bool, const Interrupter*);

}  // namespace distband::separable_internal
