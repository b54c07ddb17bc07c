// BandState: what one engine run shares between its parts (propagation, second ring, emission, the run loop): the
// inputs, the stencil's link tables, the brick table, the current segment's thresholds, per-thread buffers and the
// bricks waiting for emission. Also the front lists' entry and allocator and the per-thread buffers.
// Contract: built once per run by BandRun (or a unit test). Fields are written by the run loop between parallel
// phases and read inside them; the brick table and per-thread buffers (buffers.local()) are used concurrently.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <sys/mman.h>

#include <tbb/enumerable_thread_specific.h>

#include "core/band/band_engine.h"
#include "core/band/internal/band_key.h"
#include "core/band/internal/brick_table.h"
#include "core/band/internal/link_table.h"
#include "core/first_touch.h"
#include "core/geometry.h"
#include "core/interrupter.h"

namespace distband::band_internal {

inline constexpr int kMaxSteps = 65000;  // expiry holds 16-bit step numbers

struct VoxelRef {
  uint32_t brick;
  uint16_t offset;
};

/// A voxel that offers a site: the site and the direction it arrived from, as of the end of the previous step.
struct FrontEntry {
  uint32_t brick;
  uint16_t offset;
  uint8_t dir;
  uint32_t site;
};

// The front lists' allocator (core/first_touch.h): a list of 2 MiB or more is mapped on its own, in huge pages (a
// front of 6 MB took ~1500 page faults of 4 KiB, ~13 µs each on some virtual machines), and unmapped when freed:
// glibc would otherwise serve large lists from its heaps once it has seen large blocks freed, and the holes they
// leave stay resident while the bricks keep growing. resize() leaves new entries uninitialised: the lists are filled
// by parallel copies right after.
template <class T>
using FrontAllocator = MappedAllocator<T>;
using FrontList = std::vector<FrontEntry, FrontAllocator<FrontEntry>>;

struct ThreadBuffers {
  FrontList next;       // voxels changed in this step (site filled in after the step)
  FrontList deferred;   // offers held back beyond the admission threshold (voxel, site)
  std::vector<uint32_t> pending;      // bricks that got their first unemitted voxel
  int64_t bricks = 0;  // allocated by this thread
  std::vector<std::pair<VoxelRef, uint64_t>> corrections;
  std::vector<VoxelRef> dirty;        // changed since the last correction round (exact mode)
  int64_t updates = 0;
};

struct SiteMetric {
  const Seeds& seeds;
  Vec3d scale{1, 1, 1};  // Grid::axisScale
  bool scaled = false;   // an anisotropic grid (on a cubic one unit space is index space)
  /// Voxel c of the engine's grid in the sites' unit space. Sites live in the space of the grid this one is a window
  /// of; integer offsets add exactly, so a tile computes the same doubles as the whole grid would. Hot loops take
  /// kScaled from `scaled` once, outside the loop.
  template <bool kScaled>
  [[gnu::always_inline]] Vec3d unitsOf(const Coord& c) const {
    const Coord o{c.x + seeds.site_offset.x, c.y + seeds.site_offset.y, c.z + seeds.site_offset.z};
    const Vec3d p{double(o.x), double(o.y), double(o.z)};
    if constexpr (kScaled) return {p.x * scale.x, p.y * scale.y, p.z * scale.z};
    return p;
  }
  Vec3d unitsOf(const Coord& c) const { return scaled ? unitsOf<true>(c) : unitsOf<false>(c); }
  // Squared distance in voxels from the unit-space point p to a site (key form), in double (the emitted value) ...
  [[gnu::always_inline]] double dist2(uint32_t site, const Vec3d& p) const {
    if (site == kNoSiteKey) return 0.0;
    if (seeds.kind == SiteKind::kPoint) return (p - seeds.points[site]).lengthSqr();
    const auto& t = seeds.triangles[site];
    return TriangleDistance(t[0], t[1], t[2]).dist2(p);
  }
  // ... and rounded to float for the key.
  [[gnu::always_inline]] float key2(uint32_t site, const Vec3d& p) const { return float(dist2(site, p)); }
};

/// Paper mode's lifespan settings (disabled in exact mode, or with alpha = +infinity).
struct Lifespan {
  Lifespan(const BandOptions& opt, const Stencil& stencil);
  double alpha = 0;
  int margin = 0;
  bool enabled = false;
  double max_link = 1;  // longest link between propagating voxels (voxels per step at best)
};

struct BandState {
  BandState(const Grid& grid, const Seeds& seeds, const BandOptions& opt);

  /// Whether the run must stop. Cheap: a relaxed load once tripped (and a clock read while a deadline is pending).
  bool stopping() const { return isInterrupted(opt.interrupter); }
  /// stopping(), polled at item i of a parallel range every `every` items (a power of two). A poll per range is not
  /// enough: TBB's auto_partitioner hands out ranges of up to 1/(4 x threads) of a loop, which at 1024^3 is a few
  /// hundred milliseconds of work. `every` keeps a poll interval near 0.1 ms of the loop's work per item.
  bool stoppingAt(size_t i, size_t every) const { return (i & (every - 1)) == 0 && stopping(); }
  uint8_t regionOf(const Coord& c) const { return region ? region[grid.denseIndex(c)] : 0; }
  uint64_t keyAt(const Coord& c) const {
    if (!grid.contains(c)) return kUntouched;
    const BrickState* b = table.find(c);
    return b ? b->key[brickOffset(c.x & 7, c.y & 7, c.z & 7)].load(std::memory_order_relaxed) : kUntouched;
  }
  /// The brick id of a voxel inside the grid, its super-block created if needed.
  uint32_t brickIdOf(const Coord& c) {
    return table.idOf({c.x >> kBrickLog2, c.y >> kBrickLog2, c.z >> kBrickLog2}, true);
  }

  // The paper's lifespan, t_max = (1 + alpha) * t_min, with t_min taken from the voxel's first distance beyond the
  // segment's lower bound (t_min = distance / longest link) rather than from its first-touch step. The two agree
  // when the band sits on the sites; the distance form stays right when it does not (seeds outside the grid, a
  // segment restarting from the finished region). See docs/algorithm.md.
  uint16_t expiryFor(float d2) const {
    const double beyond = std::max(0.0, std::sqrt(double(d2)) - lower_vox);
    const double exp = segment_start_step + std::ceil((1.0 + lifespan.alpha) * beyond / lifespan.max_link) +
                       lifespan.margin;
    return uint16_t(std::min(exp, double(kMaxSteps)));
  }

  const Grid& grid;
  const Seeds& seeds;
  const BandOptions& opt;
  const Stencil& stencil;
  SiteMetric metric;
  Coord dims;
  const uint8_t* region;  // Seeds::region's labels, or null
  LinkTables links;
  Lifespan lifespan;
  BrickTable table;
  double limit_vox = 0, segment_vox = 0;
  // The slacks' factor: a lattice path runs up to a voxel step off its straight line, and a step along an axis is
  // up to Grid::maxAxisScale() units long (1 on a cubic grid).
  double slack_scale = 1;

  // The current segment (set by the run loop between phases).
  int step = 0;
  int segment_start_step = 0;
  double lower_vox = 0;        // the segment's lower distance bound
  float thr2 = 0;              // voxels within this squared distance are delivered at the end of the segment
  float admit2 = 0;            // offers beyond this squared distance wait for a later segment
  float frozen2 = -1;          // voxels at or below this squared distance are final (delivered)
  bool thr_is_limit = false;
  bool defer = false;          // offers beyond admit2 are held back for a later slice or segment (not past the limit)
  bool collect_dirty = false;  // exact mode: after a segment's first correction round

  tbb::enumerable_thread_specific<ThreadBuffers> buffers;
  std::vector<uint32_t> pending_bricks;  // bricks holding undelivered voxels, in (z, y, x) order of origins
  FrontList deferred;                    // held-back offers collected from the threads
  int64_t corrections = 0;               // voxels improved by the second ring
};

}  // namespace distband::band_internal
