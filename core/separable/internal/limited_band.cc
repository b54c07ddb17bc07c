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

#include "core/brick.h"
#include "core/separable/internal/lines.h"

namespace distband::separable_internal {
namespace {

constexpr int kStride[3] = {64, 8, 1};              // brickOffset's step along x, y, z
constexpr int kWindowReach = 16;                    // see squaredDistancesWithin
constexpr uint32_t kWindowFar = uint32_t(1) << 30;  // "far" inside the window minimum: far + reach^2 cannot wrap

bool hasZeroByte(uint64_t w) { return ((w - 0x0101010101010101ull) & ~w & 0x8080808080808080ull) != 0; }

int along(const Coord& c, int axis) { return axis == 0 ? c.x : axis == 1 ? c.y : c.z; }

/// Bricks of one pass, in runs of consecutive bricks along the pass's axis. `slot` indexes the pool; a brick whose
/// slot holds no values yet (the growth added it) starts all kFarSquared.
struct Runs {
  struct Run {
    int other[2];  // the run's brick coordinates on the two other axes (ascending axis order)
    int lo, hi;    // brick range along the axis, inclusive
    size_t first;  // its first brick in `slot`
  };
  std::vector<Run> runs;
  std::vector<uint32_t> slot;
  std::vector<uint8_t> seed;  // the brick was listed, not added by the growth (pass 1: it holds a seed's boundary)
};

/// Brick values by slot: null until the brick holds a value (bricks live in a BrickArena).
using Pool = std::vector<uint32_t*>;

/// Where bricks live: carved from slabs, one open slab per thread. First touches of fresh memory are a large part of
/// a pass's cost (page faults are slow on virtual machines): 2 MiB slabs ask for transparent huge pages, and a brick
/// is only allocated once it holds a value.
class BrickArena {
 public:
  static constexpr size_t kBrickBytes = kBrickVoxels * sizeof(uint32_t);
  // Each thread's slabs double from 64 KiB to 2 MiB, so a small band does not hold megabytes per thread (the space a
  // thread's open slab leaves unused is at most what it already holds, plus 64 KiB), and a large one gets huge pages.
  static constexpr size_t kFirstSlabBytes = size_t(64) << 10, kHugeSlabBytes = size_t(2) << 20;
  uint32_t* allocate() {
    Local& l = local_.local();
    if (l.left == 0) {
      const size_t bytes = l.slab_bytes;
      void* p = std::aligned_alloc(bytes, bytes);
      if (!p) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
      if (bytes == kHugeSlabBytes) ::madvise(p, bytes, MADV_HUGEPAGE);  // advice only: without it, 4 KiB pages
#endif
      l.slabs.emplace_back(p, std::free);
      l.next = static_cast<uint32_t*>(p);
      l.left = bytes / kBrickBytes;
      l.slab_bytes = std::min(2 * bytes, kHugeSlabBytes);
    }
    --l.left;
    uint32_t* b = l.next;
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
    uint32_t* next = nullptr;
    size_t left = 0;
    size_t slab_bytes = kFirstSlabBytes;
  };
  tbb::enumerable_thread_specific<Local> local_;
};

/// Groups `bricks` (their coordinates and pool slots; slot kNoSlot: not allocated yet) along `axis`, dilated by
/// `reach` bricks along it, into runs. Bricks the dilation adds get fresh slots at the end of the pool.
constexpr uint32_t kNoSlot = ~uint32_t(0);
struct BrickRef {
  int c[3];
  uint32_t slot;
};
Runs buildRuns(std::vector<BrickRef>& bricks, int axis, int reach, const Coord& brick_dims, Pool& pool) {
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
      const int lo = std::max(0, bricks[k].c[axis] - reach);
      int hi = std::min(n_axis - 1, bricks[k].c[axis] + reach);
      size_t m = k + 1;
      while (m < j && bricks[m].c[axis] - reach <= hi + 1) hi = std::min(n_axis - 1, bricks[m++].c[axis] + reach);
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

/// Per-thread scratch of a line pass: a line's input and output, and the envelope's stacks.
struct LineScratch {
  std::vector<uint32_t> f, d;
  std::vector<int> v;
  std::vector<double> z;
  std::vector<std::array<uint32_t, kBrickSize>> lanes;  // eight lines side by side, padded by the reach both ways
  LineScratch(int n, int reach)
      : f(size_t(n)), d(size_t(n)), v(size_t(n)), z(size_t(n) + 1), lanes(size_t(n) + 2 * size_t(reach)) {}
};

/// Runs `lines(run index, base, w_end, length, brick values, scratch)` for every eight lines of voxels of every run
/// that share their local coordinate u on the first other axis: line w (< w_end, inside the grid) is voxel offset
/// base + w * kStride[second other axis] + i * kStride[axis] of brick i / 8 at position i < length. In parallel over
/// runs. A run's fresh bricks are worked on in scratch and allocated from `arena` only if they got a value. False
/// when interrupted.
template <typename Lines>
bool forEachLines(const Runs& r, int axis, const Coord& dims, int reach_voxels, Pool& pool, BrickArena& arena,
                  const Interrupter* interrupter, const Lines& lines) {
  const int o0 = axis == 0 ? 1 : 0, o1 = axis == 2 ? 1 : 2;
  const int n[3] = {dims.x, dims.y, dims.z};
  // Scratch per thread, not per range: ranges are a few runs each, and fresh buffers cost more than the runs' lines.
  tbb::enumerable_thread_specific<LineScratch> scratches(n[axis], reach_voxels);
  tbb::enumerable_thread_specific<std::vector<uint32_t*>> brick_lists;
  tbb::enumerable_thread_specific<std::vector<uint32_t>> fresh_scratch;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, r.runs.size(), 4), [&](const tbb::blocked_range<size_t>& range) {
    std::vector<uint32_t*>& bricks = brick_lists.local();
    std::vector<uint32_t>& fresh = fresh_scratch.local();
    LineScratch& scratch = scratches.local();
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
          std::fill(bricks[i], bricks[i] + kBrickVoxels, kFarSquared);
        }
      }
      const int length = std::min(int(count) * kBrickSize, n[axis] - run.lo * kBrickSize);
      const int u_end = std::min(kBrickSize, n[o0] - run.other[0] * kBrickSize);
      const int w_end = std::min(kBrickSize, n[o1] - run.other[1] * kBrickSize);
      for (int u = 0; u < u_end; ++u) lines(ri, u, u * kStride[o0], w_end, length, bricks.data(), scratch);
      for (size_t i = 0; i < count; ++i) {
        uint32_t*& slot = pool[r.slot[run.first + i]];
        const uint32_t* v = bricks[i];
        if (slot || std::all_of(v, v + kBrickVoxels, [](uint32_t x) { return x == kFarSquared; })) continue;
        slot = arena.allocate();
        std::copy(v, v + kBrickVoxels, slot);
      }
    }
  });
  return !isInterrupted(interrupter);
}

}  // namespace

const uint32_t* SquaredBricks::find(uint64_t key) const {
  const auto it = std::lower_bound(keys.begin(), keys.end(), key);
  return it != keys.end() && *it == key ? values[size_t(it - keys.begin())] : nullptr;
}

std::vector<uint8_t> classifyMaskBricks(const Grid& grid, const std::vector<uint8_t>& mask,
                                        const Interrupter* interrupter) {
  const Coord dims = grid.dims(), bd = grid.brickDims();
  std::vector<uint8_t> kinds(size_t(grid.brickCount()));
  // One line of bricks (by, bz) at a time: its 64 voxel rows are read front to back, a word per brick.
  tbb::parallel_for(tbb::blocked_range<size_t>(0, size_t(bd.y) * bd.z, 4), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<uint8_t> any(size_t(bd.x)), all(size_t(bd.x));
    for (size_t line = r.begin(); line != r.end(); ++line) {
      if (isInterrupted(interrupter)) return;
      const int by = int(line % size_t(bd.y)), bz = int(line / size_t(bd.y));
      std::fill(any.begin(), any.end(), 0);
      std::fill(all.begin(), all.end(), 1);
      for (int z = bz * kBrickSize; z < std::min(dims.z, (bz + 1) * kBrickSize); ++z)
        for (int y = by * kBrickSize; y < std::min(dims.y, (by + 1) * kBrickSize); ++y) {
          const uint8_t* row = mask.data() + (size_t(z) * dims.y + y) * dims.x;
          int bx = 0;
          for (; (bx + 1) * kBrickSize <= dims.x; ++bx) {
            uint64_t word;
            std::memcpy(&word, row + bx * kBrickSize, sizeof word);
            any[size_t(bx)] |= word != 0;
            all[size_t(bx)] &= !hasZeroByte(word);
          }
          for (int x = bx * kBrickSize; x < dims.x; ++x) {  // a partial brick at the far face
            any[size_t(bx)] |= row[x] != 0;
            all[size_t(bx)] &= row[x] != 0;
          }
        }
      uint8_t* out = kinds.data() + line * size_t(bd.x);
      for (size_t bx = 0; bx < size_t(bd.x); ++bx)
        out[bx] = !any[bx] ? kNoMaskVoxel : all[bx] ? kAllMaskVoxels : kSomeMaskVoxels;
    }
  });
  return kinds;
}

bool squaredDistancesWithin(const Grid& grid, const std::vector<uint8_t>& mask, const std::vector<uint8_t>& kinds,
                            bool seeds_nonzero, uint32_t cut2, const Interrupter* interrupter, SquaredBricks* out) {
  const Coord dims = grid.dims(), bd = grid.brickDims();
  const uint8_t all_seeds = seeds_nonzero ? kAllMaskVoxels : kNoMaskVoxel;
  const uint8_t no_seeds = seeds_nonzero ? kNoMaskVoxel : kAllMaskVoxels;
  // The bricks holding a seed's boundary: mixed ones, and all-seed ones beside a brick that is not all seeds.
  std::vector<std::vector<BrickRef>> per_slab(size_t(bd.z));
  tbb::parallel_for(0, bd.z, [&](int bz) {
    if (isInterrupted(interrupter)) return;
    for (int by = 0; by < bd.y; ++by)
      for (int bx = 0; bx < bd.x; ++bx) {
        const uint8_t kind = kinds[size_t(grid.brickIndex({bx, by, bz}))];
        bool boundary = kind == kSomeMaskVoxels;
        if (kind == all_seeds)
          for (int a = 0; a < 3 && !boundary; ++a)
            for (int s : {-1, 1}) {
              int nc[3] = {bx, by, bz};
              nc[a] += s;
              if (nc[a] < 0 || nc[a] >= along(bd, a)) continue;
              if (kinds[size_t(grid.brickIndex({nc[0], nc[1], nc[2]}))] != all_seeds) boundary = true;
            }
        if (boundary && kind != no_seeds) per_slab[size_t(bz)].push_back({{bx, by, bz}, kNoSlot});
      }
  });
  if (isInterrupted(interrupter)) return false;
  std::vector<BrickRef> bricks;
  for (auto& slab : per_slab) bricks.insert(bricks.end(), slab.begin(), slab.end());
  std::vector<std::vector<BrickRef>>().swap(per_slab);

  const int reach_voxels = int(std::floor(std::sqrt(double(cut2))));
  const int reach_bricks = (reach_voxels + kBrickSize - 1) / kBrickSize;
  const auto keep = [cut2](uint32_t d2) { return d2 <= cut2 ? d2 : kFarSquared; };
  // Passes 2 and 3 take the minimum over the reach directly (2 reach + 1 candidates a voxel, eight lines at once)
  // when that is cheaper than the envelope's per-voxel bookkeeping: limits up to ~16 voxels.
  const bool window = reach_voxels <= kWindowReach;
  Pool pool;
  BrickArena arena;
  // Pass 1, along x: each voxel's squared distance to the nearest seed of its row (within the boundary bricks).
  Runs runs = buildRuns(bricks, 0, reach_bricks, bd, pool);
  const bool ok1 = forEachLines(
      runs, 0, dims, reach_voxels, pool, arena, interrupter,
      [&](size_t ri, int u, int base, int w_end, int length, uint32_t* const* values, LineScratch&) {
        const Runs::Run& run = runs.runs[ri];
        const uint8_t* seed_brick = runs.seed.data() + run.first;
        for (int w = 0; w < w_end; ++w) {
          const size_t y = size_t(run.other[0]) * kBrickSize + size_t(u),
                       z = size_t(run.other[1]) * kBrickSize + size_t(w);
          const uint8_t* row = mask.data() + (z * size_t(dims.y) + y) * size_t(dims.x) + size_t(run.lo) * kBrickSize;
          const int line = base + w * kStride[2];
          auto isSeed = [&](int i) { return seed_brick[i / kBrickSize] && (row[i] != 0) == seeds_nonzero; };
          int last = -1;
          for (int i = 0; i < length; ++i) {
            if (isSeed(i)) last = i;
            if (last >= 0)
              values[i / kBrickSize][line + (i % kBrickSize) * kStride[0]] = keep(uint32_t((i - last) * (i - last)));
          }
          last = -1;
          for (int i = length - 1; i >= 0; --i) {
            if (isSeed(i)) last = i;
            if (last < 0) continue;
            uint32_t& v = values[i / kBrickSize][line + (i % kBrickSize) * kStride[0]];
            v = std::min(v, keep(uint32_t((last - i) * (last - i))));
          }
        }
      });
  if (!ok1) return false;
  // Passes 2 and 3, along y and z: the lower envelope of the previous pass's parabolas on each line.
  for (int axis : {1, 2}) {
    bricks = liveBricks(runs, axis == 1 ? 0 : 1, pool);
    runs = buildRuns(bricks, axis, reach_bricks, bd, pool);
    const int o1 = axis == 2 ? 1 : 2;  // the second other axis: the lanes of a bundle
    const bool ok =
        forEachLines(runs, axis, dims, reach_voxels, pool, arena, interrupter,
                     [&](size_t, int, int base, int w_end, int length, uint32_t* const* values, LineScratch& s) {
                       auto at = [&](int i, int w) -> uint32_t& {
                         return values[i / kBrickSize][base + w * kStride[o1] + (i % kBrickSize) * kStride[axis]];
                       };
                       if (window) {
                         // Eight lines at once, side by side, padded by reach_voxels far rows at each end.
                         auto* lane = s.lanes.data() + reach_voxels;
                         bool any = false;
                         for (int i = -reach_voxels; i < length + reach_voxels; ++i) lane[i].fill(kWindowFar);
                         for (int i = 0; i < length; ++i)
                           for (int w = 0; w < w_end; ++w) {
                             const uint32_t f = at(i, w);
                             any |= f != kFarSquared;
                             if (f != kFarSquared) lane[i][size_t(w)] = f;
                           }
                         if (!any) return;
                         for (int i = 0; i < length; ++i) {
                           std::array<uint32_t, kBrickSize> m = lane[i];
                           for (int k = 1; k <= reach_voxels; ++k) {
                             const uint32_t kk = uint32_t(k * k);
                             const auto& lo = lane[i - k];
                             const auto& hi = lane[i + k];
                             for (size_t w = 0; w < kBrickSize; ++w) m[w] = std::min(m[w], std::min(lo[w], hi[w]) + kk);
                           }
                           for (int w = 0; w < w_end; ++w) at(i, w) = keep(m[size_t(w)]);
                         }
                         return;
                       }
                       for (int w = 0; w < w_end; ++w) {
                         bool any = false;
                         for (int i = 0; i < length; ++i) {
                           s.f[size_t(i)] = at(i, w);
                           any |= s.f[size_t(i)] != kFarSquared;
                         }
                         if (!any) continue;
                         parabolaEnvelope(s.f.data(), s.d.data(), length, 1.0, s.v.data(), s.z.data());
                         for (int i = 0; i < length; ++i) at(i, w) = keep(s.d[size_t(i)]);
                       }
                     });
    if (!ok) return false;
  }
  bricks = liveBricks(runs, 2, pool);
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

}  // namespace distband::separable_internal
