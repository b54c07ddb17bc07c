#include "core/band/internal/emission.h"

#include <algorithm>
#include <utility>

#include <malloc.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/interruptible.h"
#include "core/separable/internal/segment_emission.h"

namespace distband::band_internal {

void collectPending(BandState& s) {
  for (auto& tb : s.buffers) {
    s.pending_bricks.insert(s.pending_bricks.end(), tb.pending.begin(), tb.pending.end());
    tb.pending.clear();
  }
  // Ids carry no position: sort (origin key, id) pairs.
  std::vector<std::pair<uint64_t, uint32_t>> keyed(s.pending_bricks.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, keyed.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i)
      keyed[i] = {BrickTable::originKey(s.table.originOf(s.pending_bricks[i])), s.pending_bricks[i]};
  });
  if (!runInterruptible(s.opt.interrupter, [&] { tbb::parallel_sort(keyed.begin(), keyed.end()); }))
    return;  // stopping() says so from now on
  keyed.erase(std::unique(keyed.begin(), keyed.end()), keyed.end());
  s.pending_bricks.resize(keyed.size());
  for (size_t i = 0; i < keyed.size(); ++i) s.pending_bricks[i] = keyed[i].second;
}

// After the last segment's bricks are built nothing reads the band again: free it before the consumer builds its
// output, so the two never peak together, and hand large amounts back (freed in the worker threads' malloc arenas,
// they would otherwise stay in this process).
void releaseBricks(BandState& s) {
  const size_t freed = s.table.releaseAll();
  // Worth a trim (a few ms) only when it hands back a sizeable amount, and not on the way out of a stopped run: the
  // next run of this process reuses the pages anyway.
  if (freed * sizeof(BrickState) >= (size_t(64) << 20) && !s.stopping()) ::malloc_trim(0);
}

bool emitSegment(BandState& s, const SegmentCallback& cb, int index, double lower_vox, double upper_vox,
                 bool nothing_deferred, SegmentStats& stats) {
  collectPending(s);
  const double h = s.grid.voxelSize();
  const std::vector<uint32_t>& pending = s.pending_bricks;
  const size_t n = pending.size();
  // Pass 1: which pending bricks deliver voxels now, and which keep voxels for later segments. The output is then
  // built in chunks of pending bricks (in (z, y, x) order of their origins). In the last segment each chunk's engine
  // bricks are freed as soon as it is built, so the output grows while the engine state shrinks instead of the two
  // peaking together.
  std::vector<uint32_t> slot(n, 0);  // 1 + position in the segment's output, or 0
  std::vector<uint8_t> keep(n, 0);
  // The limit's segment is the last whatever waits beyond it (nothing is ever delivered there), so a brick's scan
  // stops at its first deliverable voxel: most bricks of a thin band have none beyond (bunny 256^3 hw20: this pass
  // was ~2 % of the engine's instructions).
  const bool need_keep = !s.thr_is_limit;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 64)) return;
      BrickState* b = s.table.get(pending[i]);
      for (int off = 0; off < kBrickVoxels && !(slot[i] && (keep[i] || !need_keep)); ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || b->emitted.test(off)) continue;
        if (keyDist2(k) > s.thr2) keep[i] = 1;
        else slot[i] = 1;
      }
    }
  });
  if (s.stopping()) return true;
  uint32_t count = 0;
  for (uint32_t& c : slot) c = c ? ++count : 0;
  bool waiting = false;
  for (uint8_t kept : keep) waiting |= kept != 0;
  const bool last = s.thr_is_limit || (nothing_deferred && !waiting);
  auto piece = [&](bool complete) {
    SegmentBricks p;
    p.index = index;
    p.lower_world = lower_vox * h;
    p.upper_world = upper_vox * h;
    p.last = last && complete;
    p.complete = complete;
    return p;
  };
  // Ranges [c0, c1) of pending bricks holding at most `per_chunk` output bricks each, built and handed over in turn.
  const size_t max_chunk = s.opt.max_chunk_bricks;
  const size_t per_chunk = max_chunk ? max_chunk : std::max<size_t>(count, 1);
  // Whole segments are built this many pending bricks at a time, and in the last one each chunk's bricks are freed
  // once it is built: with 8192 a 512^3 teapot's ~11 k bricks were two chunks, its engine bricks nearly all held
  // until the output was whole (both were its peak: 75 MiB; 61 MiB with 1024).
  constexpr size_t kBuildBricks = 1024;
  SegmentBricks whole = piece(true);
  whole.bricks.reserve(max_chunk ? 0 : count);
  std::vector<Brick> part;
  if (last) s.table.drain();  // the bricks freed below give their memory back as their chunks empty
  size_t freed_bytes = 0;
  uint32_t base = 0;  // output bricks before c0
  for (size_t c0 = 0; c0 < n || (c0 == 0 && n == 0);) {
    if (s.stopping()) return true;
    size_t c1 = c0, outs = 0;
    while (c1 < n && outs < per_chunk && c1 - c0 < kBuildBricks) outs += slot[c1++] != 0;
    // Whole segments are built where they are delivered (no second copy of 2 KiB a brick on one thread); chunks apart.
    std::vector<Brick>& out = max_chunk ? part : whole.bricks;
    if (max_chunk) part.clear();
    appendUnsetBricks(out, outs);  // buildChunk writes every value
    buildChunk(s, c0, c1, slot, keep, max_chunk ? base : 0, out);
    if (last) {
      // Distinct bricks: freed in parallel (a serial loop of frees was a serial phase of the last segment).
      tbb::parallel_for(tbb::blocked_range<size_t>(c0, c1, 256), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) s.table.release(pending[i]);
      });
      // The bricks' own chunks are unmapped as they empty (BrickPool); paper mode's lifespans are on the heap.
      if (s.lifespan.enabled) freed_bytes += (c1 - c0) * kBrickVoxels * sizeof(uint16_t);
      if (freed_bytes >= (size_t(64) << 20) && c1 < n) {
        ::malloc_trim(0);  // their pages back before the next chunk's output (the last: below)
        freed_bytes = 0;
      }
    }
    for (size_t i = out.size() - outs; i < out.size(); ++i) stats.voxels += out[i].mask.count();
    stats.bricks += int64_t(outs);
    base += uint32_t(outs);
    const bool done = c1 >= n;
    if (max_chunk) {
      if (s.stopping()) return true;
      SegmentBricks p = piece(done);
      p.bricks = std::move(part);
      if (cb) cb(std::move(p));
    }
    if (done) break;
    c0 = c1;
  }
  std::vector<Brick>().swap(part);
  if (last) releaseBricks(s);
  size_t w = 0;
  for (size_t i = 0; i < n; ++i)
    if (keep[i]) s.pending_bricks[w++] = s.pending_bricks[i];
  s.pending_bricks.resize(w);
  if (!max_chunk && cb && !s.stopping()) cb(std::move(whole));
  return last;
}

int64_t closestFeature(const BandState& s, uint32_t site, const Coord& voxel) {
  if (s.seeds.feature_kind == Seeds::FeatureKind::kSiteVoxel) {
    if (site == kNoSite) return s.grid.denseIndex(voxel);  // inside the seed volume: its own feature
    const Vec3d& p = s.seeds.points[site];  // a voxel's centre in unit space
    const Coord o = s.seeds.site_offset;
    const Vec3d& r = s.metric.scale;
    return s.grid.denseIndex({int(std::lround(p.x / r.x)) - o.x, int(std::lround(p.y / r.y)) - o.y,
                              int(std::lround(p.z / r.z)) - o.z});
  }
  if (site == kNoSite) return -1;
  return s.seeds.site_feature.empty() ? int64_t(site) : int64_t(s.seeds.site_feature[site]);
}

void buildChunk(BandState& s, size_t c0, size_t c1, const std::vector<uint32_t>& slot,
                const std::vector<uint8_t>& keep, uint32_t base, std::vector<Brick>& out) {
  const double h = s.grid.voxelSize();
  const bool triangles = s.seeds.kind == SiteKind::kTriangle;
  const bool closest = s.opt.closest_features;
  // Compiled for cubic and anisotropic grids (a point site's distance takes the voxel's unit-space position).
  auto fill = [&](const tbb::blocked_range<size_t>& r, auto scaled_tag) {
    constexpr bool kScaled = decltype(scaled_tag)::value;
    uint32_t sites[kBrickVoxels];
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stopping()) return;  // per brick: a mesh's winding-number sign can take milliseconds a brick
      BrickState* b = s.table.get(s.pending_bricks[i]);
      if (!keep[i]) b->pending.store(false, std::memory_order_relaxed);
      if (!slot[i]) continue;
      Brick& brick = out[slot[i] - 1 - base];
      brick.origin = b->origin;
      if (closest) brick.closest.assign(kBrickVoxels, -1);
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        sites[off] = kNoSite;
        brick.values[off] = 0;  // not delivered (the bricks were made without values: appendUnsetBricks)
        if (k == kUntouched || keyDist2(k) > s.thr2) continue;
        if (b->emitted.test(off)) continue;
        const Coord c = b->origin + brickLocal(off);
        const uint32_t site = keySite(k);
        sites[off] = site == kNoSiteKey ? kNoSite : site;
        // Triangle sites: the key's float squared distance is the exact one rounded to 24 bits, so its root is within
        // an ulp of the output's float (a second point–triangle test per voxel would buy nothing). Points are cheap.
        const double d2 = triangles ? double(keyDist2(k)) : s.metric.dist2(site, s.metric.unitsOf<kScaled>(c));
        brick.values[off] = float(std::sqrt(d2) * h);
        brick.mask.set(off);
        if (closest) brick.closest[off] = closestFeature(s, sites[off], c);
      }
      for (size_t w = 0; w < brick.mask.words.size(); ++w)
        b->emitted.words[w].fetch_or(brick.mask.words[w], std::memory_order_relaxed);
      if (s.seeds.sign) s.seeds.sign(brick, sites);
    }
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(c0, c1, 16), [&](const tbb::blocked_range<size_t>& r) {
    s.metric.scaled ? fill(r, std::true_type{}) : fill(r, std::false_type{});
  });
}

}  // namespace distband::band_internal
