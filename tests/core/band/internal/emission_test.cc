// Tests for core/engine/emission: bricks handed over in (z, y, x) order of origins whatever order they were created
// in, each voxel delivered once and only within the segment's threshold, voxels beyond it kept for a later segment,
// chunking (at most N bricks a chunk, the same order, the last marked complete), and closest-feature ids.
#include "core/band/internal/emission.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "core/band/internal/propagation.h"

namespace distband::band_internal {
namespace {

struct Fixture {
  // Several super-blocks of the brick table along x and z, created in random order: ids do not follow origins.
  Grid grid{{0, 0, 0}, 0.5, {280, 48, 150}};
  Seeds seeds;
  BandOptions opt;
  Fixture() {
    seeds.kind = SiteKind::kPoint;
    seeds.points = {{20, 20, 20}};
  }
};

// Touches `voxels` (site 0, its true distance) through offer(), as propagation does, in the given order.
void touch(BandState& s, const std::vector<Coord>& voxels) {
  ThreadBuffers& tb = s.buffers.local();
  for (const Coord& c : voxels) {
    const uint32_t id = s.brickIdOf(c);
    BrickState* b = s.table.getOrCreate(id, &tb.bricks);
    offer(s, b, id, brickOffset(c.x & 7, c.y & 7, c.z & 7), packKey(s.metric.key2(0, s.metric.unitsOf(c)), kNoDirection, 0),
          false, tb);
  }
}

std::vector<Coord> shuffledVoxels(int count, unsigned seed, const Coord& dims) {
  std::mt19937 rng(seed);
  std::vector<Coord> v;
  for (int i = 0; i < count; ++i) v.push_back({int(rng() % dims.x), int(rng() % dims.y), int(rng() % dims.z)});
  return v;
}

std::tuple<int, int, int> zyx(const Coord& c) { return {c.z, c.y, c.x}; }

TEST(Emission, SegmentsDeliverEachVoxelOnceInOriginOrder) {
  Fixture f;
  BandState s(f.grid, f.seeds, f.opt);
  const std::vector<Coord> voxels = shuffledVoxels(3000, 5, f.grid.dims());
  touch(s, voxels);
  std::map<std::tuple<int, int, int>, int> delivered;
  std::vector<SegmentBricks> segments;
  auto cb = [&](SegmentBricks&& seg) { segments.push_back(std::move(seg)); };
  const double bounds[] = {30.0, 120.0};  // voxels; the farthest voxel is ~280 away
  for (int seg = 0; seg < 3; ++seg) {
    const double upper = seg < 2 ? bounds[seg] : INFINITY;
    s.thr2 = std::isfinite(upper) ? float(upper * upper) : INFINITY;
    s.thr_is_limit = seg == 2;
    SegmentStats stats;
    const bool last = emitSegment(s, cb, seg, seg ? bounds[seg - 1] : 0.0, upper, true, stats);
    EXPECT_EQ(last, seg == 2);
    s.frozen2 = s.thr2;
  }
  ASSERT_EQ(segments.size(), 3u);
  for (int seg = 0; seg < 3; ++seg) {
    const SegmentBricks& p = segments[size_t(seg)];
    EXPECT_EQ(p.index, seg);
    EXPECT_TRUE(p.complete);
    EXPECT_EQ(p.last, seg == 2);
    EXPECT_DOUBLE_EQ(p.lower_world, seg ? bounds[seg - 1] * 0.5 : 0.0);
    for (size_t i = 1; i < p.bricks.size(); ++i) EXPECT_LT(zyx(p.bricks[i - 1].origin), zyx(p.bricks[i].origin));
    for (const Brick& b : p.bricks) {
      EXPECT_FALSE(b.mask.empty());
      for (int off = 0; off < kBrickVoxels; ++off) {
        if (!b.mask.test(off)) continue;
        const Coord c = b.origin + brickLocal(off);
        ++delivered[zyx(c)];
        const double d = std::sqrt(double(c.x - 20) * (c.x - 20) + double(c.y - 20) * (c.y - 20) +
                                   double(c.z - 20) * (c.z - 20));
        EXPECT_FLOAT_EQ(b.values[off], float(d * 0.5));
        if (seg < 2) {
          EXPECT_LE(d, bounds[seg]);
        }
        if (seg > 0) {
          EXPECT_GT(d, bounds[seg - 1]);
        }
      }
    }
  }
  std::map<std::tuple<int, int, int>, int> expected;
  for (const Coord& c : voxels) expected[zyx(c)] = 1;
  EXPECT_EQ(delivered, expected);  // every touched voxel exactly once
  EXPECT_TRUE(s.pending_bricks.empty());
  EXPECT_EQ(s.table.brickAt({0, 0, 0}), nullptr);  // the last segment frees the engine's bricks
}

TEST(Emission, ChunksKeepTheOrderAndTheLastIsComplete) {
  Fixture f;
  f.opt.max_chunk_bricks = 3;
  BandState s(f.grid, f.seeds, f.opt);
  touch(s, shuffledVoxels(400, 9, f.grid.dims()));
  const size_t bricks = size_t(s.buffers.local().bricks);
  std::vector<SegmentBricks> chunks;
  s.thr2 = INFINITY;
  s.thr_is_limit = true;
  SegmentStats stats;
  EXPECT_TRUE(emitSegment(s, [&](SegmentBricks&& p) { chunks.push_back(std::move(p)); }, 0, 0, INFINITY, true, stats));
  ASSERT_EQ(chunks.size(), (bricks + 2) / 3);
  std::vector<Coord> origins;
  for (size_t i = 0; i < chunks.size(); ++i) {
    EXPECT_LE(chunks[i].bricks.size(), 3u);
    EXPECT_EQ(chunks[i].complete, i + 1 == chunks.size());
    EXPECT_EQ(chunks[i].last, i + 1 == chunks.size());
    for (const Brick& b : chunks[i].bricks) origins.push_back(b.origin);
  }
  EXPECT_EQ(origins.size(), bricks);
  for (size_t i = 1; i < origins.size(); ++i) EXPECT_LT(zyx(origins[i - 1]), zyx(origins[i]));
  EXPECT_EQ(stats.bricks, int64_t(bricks));
}

TEST(Emission, ClosestFeatureIds) {
  Fixture f;
  BandState s(f.grid, f.seeds, f.opt);
  EXPECT_EQ(closestFeature(s, 0, {1, 2, 3}), 0);
  EXPECT_EQ(closestFeature(s, kNoSite, {1, 2, 3}), -1);
  f.seeds.site_feature = {42};
  EXPECT_EQ(closestFeature(s, 0, {1, 2, 3}), 42);
  f.seeds.feature_kind = Seeds::FeatureKind::kSiteVoxel;
  EXPECT_EQ(closestFeature(s, 0, {1, 2, 3}), f.grid.denseIndex({20, 20, 20}));
  EXPECT_EQ(closestFeature(s, kNoSite, {1, 2, 3}), f.grid.denseIndex({1, 2, 3}));
}

}  // namespace
}  // namespace distband::band_internal
