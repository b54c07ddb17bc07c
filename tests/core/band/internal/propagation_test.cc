// Tests for core/engine/propagation: offer() (only a lower key is taken; a brick is listed for emission once, a
// voxel in the next front once per step), band insertion (keys, the limit, invalid bands), one step from a point
// site (every neighbour gets the site at its exact float distance), held-back offers beyond the admission threshold
// and their replay, and the front's snapshot of site and direction.
#include "core/band/internal/propagation.h"

#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace distband::band_internal {
namespace {

struct Fixture {
  Grid grid{{0, 0, 0}, 1.0, {24, 24, 24}};
  Seeds seeds;
  BandOptions opt;
  explicit Fixture(Coord site = {12, 12, 12}) {
    seeds.kind = SiteKind::kPoint;
    seeds.points = {{double(site.x), double(site.y), double(site.z)}};
    seeds.band = {{site, 0}};
  }
};

float dist2(const Coord& a, const Coord& b) {
  const double x = a.x - b.x, y = a.y - b.y, z = a.z - b.z;
  return float(x * x + y * y + z * z);
}

TEST(Propagation, OfferTakesOnlyALowerKeyAndListsOnce) {
  Fixture f;
  BandState s(f.grid, f.seeds, f.opt);
  ThreadBuffers& tb = s.buffers.local();
  const uint32_t id = s.brickIdOf({9, 9, 9});
  BrickState* b = s.table.getOrCreate(id, &tb.bricks);
  const int off = brickOffset(1, 1, 1);
  EXPECT_TRUE(offer(s, b, id, off, packKey(9.0f, 3, 0), true, tb));
  EXPECT_FALSE(offer(s, b, id, off, packKey(9.0f, 4, 0), true, tb));  // same distance and site, later direction
  EXPECT_FALSE(offer(s, b, id, off, packKey(10.0f, 0, 0), true, tb));
  EXPECT_TRUE(offer(s, b, id, off, packKey(9.0f, 0, 0), true, tb));
  EXPECT_TRUE(offer(s, b, id, off + 1, packKey(4.0f, 0, 0), false, tb));  // does not propagate: not listed
  EXPECT_EQ(b->key[off].load(), packKey(9.0f, 0, 0));
  EXPECT_EQ(tb.updates, 3);
  ASSERT_EQ(tb.pending.size(), 1u);  // the brick, once
  EXPECT_EQ(tb.pending[0], id);
  ASSERT_EQ(tb.next.size(), 1u);  // the voxel, once this step
  EXPECT_EQ(tb.next[0].offset, off);
  EXPECT_TRUE(tb.dirty.empty());  // only collected after a segment's first correction round
}

TEST(Propagation, InsertBandWritesKeysAndRejectsBadBands) {
  Fixture f;
  f.seeds.band.push_back({{12, 12, 13}, 0});
  BandState s(f.grid, f.seeds, f.opt);
  insertBand(s);
  EXPECT_EQ(s.keyAt({12, 12, 12}), packKey(0.0f, kNoDirection, 0));
  EXPECT_EQ(s.keyAt({12, 12, 13}), packKey(1.0f, kNoDirection, 0));
  EXPECT_EQ(s.keyAt({12, 13, 12}), kUntouched);
  Fixture outside;
  outside.seeds.band.push_back({{24, 0, 0}, 0});
  BandState so(outside.grid, outside.seeds, outside.opt);
  EXPECT_THROW(insertBand(so), std::invalid_argument);
  Fixture bad_site;
  bad_site.seeds.band.push_back({{1, 1, 1}, 1});
  BandState sb(bad_site.grid, bad_site.seeds, bad_site.opt);
  EXPECT_THROW(insertBand(sb), std::invalid_argument);
  // Beyond the limit (plus its one-voxel slack) a band voxel is not inserted.
  Fixture limited;
  limited.opt.limit_world = 2.0;
  limited.seeds.band.push_back({{12, 12, 16}, 0});
  BandState sl(limited.grid, limited.seeds, limited.opt);
  insertBand(sl);
  EXPECT_EQ(sl.keyAt({12, 12, 16}), kUntouched);
}

TEST(Propagation, OneStepReachesEveryNeighbourAcrossBricks) {
  const Coord site{8, 8, 8};  // a brick corner: the step crosses into 7 neighbouring bricks
  Fixture f(site);
  BandState s(f.grid, f.seeds, f.opt);
  s.admit2 = INFINITY;
  insertBand(s);
  FrontList front;
  gatherFront(s, front);
  ASSERT_EQ(front.size(), 1u);
  EXPECT_EQ(front[0].site, 0u);
  EXPECT_EQ(front[0].dir, kNoDirection);
  for (auto& tb : s.buffers) tb.next.reserve(8192);  // above the next lists' least share (reserveNext)
  step(s, front);
  std::vector<const FrontEntry*> next_storage;
  for (auto& tb : s.buffers) next_storage.push_back(tb.next.data());
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const Coord c{site.x + dx, site.y + dy, site.z + dz};
        const uint64_t k = s.keyAt(c);
        ASSERT_NE(k, kUntouched);
        EXPECT_EQ(keySite(k), 0u);
        EXPECT_EQ(keyDist2(k), dist2(c, site));
        if (dx || dy || dz) {
          EXPECT_EQ(s.stencil.links[keyDir(k)], (Coord{dx, dy, dz}));
        }
      }
  EXPECT_EQ(s.keyAt({site.x + 2, site.y, site.z}), kUntouched);
  // The next front is written over the last one, in its storage when that is large enough.
  front.reserve(64);
  const FrontEntry* const storage = front.data();
  gatherFront(s, front);
  EXPECT_EQ(front.size(), 26u);
  EXPECT_EQ(front.data(), storage);
  for (const FrontEntry& e : front) {
    EXPECT_EQ(e.site, 0u);
    EXPECT_NE(e.dir, kNoDirection);
  }
  int64_t bricks = 0;
  for (auto& tb : s.buffers) bricks += tb.bricks;
  EXPECT_EQ(bricks, 8);
  // The threads' next lists were emptied and keep their storage until releaseFronts.
  size_t i = 0;
  for (auto& tb : s.buffers) {
    EXPECT_TRUE(tb.next.empty());
    ASSERT_LT(i, next_storage.size());
    EXPECT_EQ(tb.next.data(), next_storage[i++]);
  }
  releaseFronts(s, front);
  EXPECT_EQ(front.capacity(), 0u);
  for (auto& tb : s.buffers) EXPECT_EQ(tb.next.capacity(), 0u);
}

TEST(Propagation, OffersBeyondTheAdmissionAreHeldBackAndReplayed) {
  Fixture f;
  BandState s(f.grid, f.seeds, f.opt);
  s.admit2 = 1.5f;  // axial neighbours (1) are admitted, diagonal ones (2, 3) are not
  s.defer = true;
  insertBand(s);
  FrontList front;
  gatherFront(s, front);
  step(s, front);
  EXPECT_NE(s.keyAt({13, 12, 12}), kUntouched);
  EXPECT_EQ(s.keyAt({13, 13, 12}), kUntouched);
  FrontList replay = takeDeferred(s);
  ASSERT_EQ(replay.size(), 1u);  // the site's voxel, once
  EXPECT_EQ(replay[0].site, 0u);
  EXPECT_EQ(replay[0].dir, kNoDirection);
  s.admit2 = INFINITY;
  step(s, replay);
  EXPECT_EQ(keyDist2(s.keyAt({13, 13, 12})), 2.0f);
  EXPECT_EQ(keyDist2(s.keyAt({11, 13, 13})), 3.0f);
}

}  // namespace
}  // namespace distband::band_internal
