#include "core/band/internal/second_ring.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/band/internal/emission.h"

namespace distband::band_internal {
namespace {

/// The 5^3 block centred on q, per axis: whether each coordinate is inside the grid, which of the (at most two)
/// bricks from b0 holds it (0 or 1), and its local index there.
struct BlockAxes {
  int b0[3];
  int sel[3][5], local[3][5];
  bool valid[3][5];
  [[gnu::always_inline]] BlockAxes(const BandState& s, const Coord& q) {
    const int qc[3] = {q.x, q.y, q.z}, dims[3] = {s.dims.x, s.dims.y, s.dims.z};
    for (int a = 0; a < 3; ++a) {
      b0[a] = (qc[a] - 2) >> kBrickLog2;
      for (int i = 0; i < 5; ++i) {
        const int c = qc[a] + i - 2;
        valid[a][i] = c >= 0 && c < dims[a];
        sel[a][i] = (c >> kBrickLog2) - b0[a];
        local[a][i] = c & 7;
      }
    }
  }
};

// The body of gatherBlock, forced inline into checkVoxel, its hot caller (one call per checked voxel): a call there
// costs more than the block gather itself.
[[gnu::always_inline]] inline void gatherBlockInline(const BandState& s, const Coord& q, uint64_t* block) {
  const BlockAxes w(s, q);
  const auto& valid = w.valid;
  const auto& bsel = w.sel;
  const auto& local = w.local;
  BrickState* bricks[2][2][2];
  s.table.bricksFrom({w.b0[0], w.b0[1], w.b0[2]}, &bricks[0][0][0], nullptr);
  const uint8_t region = s.regionOf(q);
  int j = 0;
  for (int iz = 0; iz < 5; ++iz)
    for (int iy = 0; iy < 5; ++iy) {
      if (!valid[2][iz] || !valid[1][iy]) {
        for (int ix = 0; ix < 5; ++ix) block[j++] = kUntouched;
        continue;
      }
      BrickState* const* row = bricks[bsel[2][iz]][bsel[1][iy]];
      const int yz = (local[1][iy] << 3) | local[2][iz];
      for (int ix = 0; ix < 5; ++ix, ++j) {
        BrickState* nb = row[bsel[0][ix]];
        uint64_t nk = kUntouched;
        if (valid[0][ix] && nb) {
          nk = nb->key[(local[0][ix] << 6) | yz].load(std::memory_order_relaxed);
          if (keySite(nk) == kNoSiteKey ||
              (s.region && s.regionOf({q.x + ix - 2, q.y + iy - 2, q.z + iz - 2}) != region))
            nk = kUntouched;
        }
        block[j] = nk;
      }
    }
}

}  // namespace

void gatherBlock(const BandState& s, const Coord& q, uint64_t* block) { gatherBlockInline(s, q, block); }

bool isBoundary(const BandState& s, const Coord& q, uint64_t k) {
  const uint8_t region = s.regionOf(q);
  for (const Link& d : s.links.all()) {
    const Coord n{q.x - d.x, q.y - d.y, q.z - d.z};
    if (!s.stencil.propagates(n)) continue;
    const uint64_t nk = s.keyAt(n);
    if (nk == kUntouched || keySite(nk) == keySite(k) || keySite(nk) == kNoSiteKey) continue;
    if (s.region && s.regionOf(n) != region) continue;
    return true;
  }
  return false;
}

// A brick whose voxels all hold one site, like its 26 neighbours, has no boundary voxel and is skipped whole: far
// from Voronoi boundaries (most of the volume for point seeds) the scan costs one pass over a brick's keys.
void scanAndCheck(BandState& s) {
  const size_t n = s.pending_bricks.size();
  constexpr uint32_t kMixed = ~uint32_t(0), kEmpty = ~uint32_t(0) - 1;
  // The one site all touched voxels of a brick hold, kMixed if they differ, kEmpty if none is touched.
  auto uniformSite = [&](const BrickState* b) {
    uint32_t u = kEmpty;
    for (int off = 0; off < kBrickVoxels && u != kMixed; ++off) {
      const uint64_t k = b->key[off].load(std::memory_order_relaxed);
      if (k == kUntouched) continue;
      u = (u == kEmpty || u == keySite(k)) ? keySite(k) : kMixed;
    }
    return u;
  };
  // Pending bricks keep theirs in scan_site; keys do not change during the scan (corrections are only recorded).
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 64)) return;
      BrickState* b = s.table.get(s.pending_bricks[i]);
      b->scan_site = uniformSite(b);
    }
  });
  if (s.stopping()) return;
  // Of any brick: pending bricks from the pass above, the others (all delivered) scanned on demand.
  auto uniformOf = [&](const BrickState* b) -> uint32_t {
    if (!b) return kEmpty;
    return b->pending.load(std::memory_order_relaxed) ? b->scan_site : uniformSite(b);
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = s.buffers.local();
    uint64_t block[125];
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 4)) return;
      const uint32_t bi = s.pending_bricks[i];
      BrickState* b = s.table.get(bi);
      const Coord bc{b->origin.x >> kBrickLog2, b->origin.y >> kBrickLog2, b->origin.z >> kBrickLog2};
      // The 27 bricks around this one (null outside the grid or untouched).
      BrickState* nbr[27];
      for (int j = 0; j < 27; ++j)
        nbr[j] = s.table.brickAt({bc.x + j % 3 - 1, bc.y + (j / 3) % 3 - 1, bc.z + j / 9 - 1});
      if (b->scan_site != kMixed && !s.region) {
        bool all_same = true;
        for (int j = 0; j < 27 && all_same; ++j) {
          if (j == 13) continue;
          const uint32_t u = uniformOf(nbr[j]);
          all_same = u == kEmpty || u == b->scan_site;
        }
        if (all_same) continue;
      }
      const bool edge = b->origin.x + kBrickSize > s.dims.x || b->origin.y + kBrickSize > s.dims.y ||
                        b->origin.z + kBrickSize > s.dims.z;
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || keyDist2(k) > s.thr2 || keyDist2(k) <= s.frozen2 || keySite(k) == kNoSiteKey) continue;
        if (b->emitted.test(off) || b->exact.test(off)) continue;
        const Coord l = brickLocal(off);
        const Coord q = b->origin + l;
        const uint32_t site = keySite(k);
        const uint8_t region = s.regionOf(q);
        bool boundary = false;
        // Links are symmetric: the neighbour q + d offers to q along -d.
        for (const Link& d : s.links.linksFor(l, kNoDirection)) {
          BrickState* nb = nbr[d.brick];
          if (!nb) continue;
          const Coord nq{q.x + d.x, q.y + d.y, q.z + d.z};
          if (edge && !s.grid.contains(nq)) continue;
          const uint64_t nk = nb->key[off + d.offset].load(std::memory_order_relaxed);
          if (nk == kUntouched || keySite(nk) == site || keySite(nk) == kNoSiteKey) continue;
          if (!s.stencil.propagates(nq) || (s.region && s.regionOf(nq) != region)) continue;
          boundary = true;
          break;
        }
        if (boundary) checkVoxel(s, {bi, uint16_t(off)}, q, k, block, tb);
      }
    }
  });
}

namespace {
template <bool kScaled>
void checkVoxelT(const BandState& s, const VoxelRef& v, const Coord& q, uint64_t k, uint64_t* block,
                 ThreadBuffers& tb) {
  gatherBlockInline(s, q, block);
  uint64_t best = k;
  uint32_t last_site = keySite(k);
  const Vec3d p = s.metric.unitsOf<kScaled>(q);
  for (int j = 0; j < 125; ++j) {
    const uint64_t nk = block[j];
    if (nk == kUntouched) continue;
    const uint32_t site = keySite(nk);
    if (site == last_site || site == keySite(best)) continue;
    last_site = site;
    const uint64_t cand = packKey(s.metric.key2(site, p), kNoDirection, site);
    if (cand < best) best = cand;
  }
  if (keySite(best) != keySite(k)) tb.corrections.push_back({v, best});
}
}  // namespace

void checkVoxel(const BandState& s, const VoxelRef& v, const Coord& q, uint64_t k, uint64_t* block,
                ThreadBuffers& tb) {
  s.metric.scaled ? checkVoxelT<true>(s, v, q, k, block, tb) : checkVoxelT<false>(s, v, q, k, block, tb);
}

FrontList correct(BandState& s, bool first_round) {
  if (first_round) {
    collectPending(s);
    scanAndCheck(s);
  } else {
    std::vector<VoxelRef> dirty;
    for (auto& tb : s.buffers) {
      dirty.insert(dirty.end(), tb.dirty.begin(), tb.dirty.end());
      tb.dirty.clear();
    }
    // Visits the touched voxels within distance 2 of every changed voxel (each changed voxel once).
    auto aroundDirty = [&](auto&& visit) {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, dirty.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          if (s.stoppingAt(i, 16)) return;
          const Coord c = s.table.originOf(dirty[i].brick) + brickLocal(dirty[i].offset);
          // The 5^3 block spans at most two bricks per axis: look the (up to) eight up once (no brick is created or
          // freed during a correction round), and per axis which of them and where in it each coordinate lies.
          const BlockAxes w(s, c);
          const auto& valid = w.valid;
          const auto& sel = w.sel;
          const auto& local = w.local;
          uint32_t ids[8];
          BrickState* bricks[8];
          s.table.bricksFrom({w.b0[0], w.b0[1], w.b0[2]}, bricks, ids);
          for (int iz = 0; iz < 5; ++iz) {
            if (!valid[2][iz]) continue;
            for (int iy = 0; iy < 5; ++iy) {
              if (!valid[1][iy]) continue;
              for (int ix = 0; ix < 5; ++ix) {
                if (!valid[0][ix]) continue;
                const int j = (sel[2][iz] << 2) | (sel[1][iy] << 1) | sel[0][ix];
                BrickState* b = bricks[j];
                if (!b) continue;
                const int off = brickOffset(local[0][ix], local[1][iy], local[2][iz]);
                if (b->key[off].load(std::memory_order_relaxed) != kUntouched)
                  visit(b, ids[j], off, Coord{c.x + ix - 2, c.y + iy - 2, c.z + iz - 2});
              }
            }
          }
        }
      });
    };
    for (const VoxelRef& d : dirty) s.table.get(d.brick)->dirty.clear(d.offset);
    // Check each candidate once, as it is claimed (queued), without listing them: corrections are only recorded
    // here and applied after the round, so which thread checks a voxel does not matter.
    aroundDirty([&](BrickState* b, uint32_t bi, int off, const Coord& q) {
      if (!b->queued.set(off)) return;
      const uint64_t k = b->key[off].load(std::memory_order_relaxed);
      if (keyDist2(k) > s.thr2 || keyDist2(k) <= s.frozen2 || keySite(k) == kNoSiteKey || b->exact.test(off) ||
          !isBoundary(s, q, k))
        return;
      uint64_t block[125];
      checkVoxel(s, {bi, uint16_t(off)}, q, k, block, s.buffers.local());
    });
    aroundDirty([&](BrickState* b, uint32_t, int off, const Coord&) {
      if (b->queued.test(off)) b->queued.clear(off);
    });
  }
  FrontList front;
  for (auto& tb : s.buffers) {
    for (const auto& [v, key] : tb.corrections) {
      BrickState* b = s.table.get(v.brick);
      b->key[v.offset].store(key, std::memory_order_relaxed);
      ++s.corrections;
      if (b->dirty.set(v.offset)) tb.dirty.push_back(v);
      if (s.stencil.propagates(b->origin + brickLocal(v.offset)))
        front.push_back({v.brick, v.offset, uint8_t(kNoDirection), keySite(key)});
    }
    tb.corrections.clear();
  }
  return front;
}


}  // namespace distband::band_internal
