// Tests for core/band/internal/brick_table: the sparse coordinate -> brick map (ids, lookups, concurrent creation,
// neighbours across super-blocks, origin order), that memory follows the touched bricks even on a 16384^3 grid, and
// the brick pool (storage reused, given back once draining).
#include "core/band/internal/brick_table.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband::band_internal {
namespace {

constexpr Coord kHugeBricks{2048, 2048, 2048};  // a 16384^3 grid

double residentMb() {
  std::ifstream statm("/proc/self/statm");
  long size = 0, resident = 0;
  statm >> size >> resident;
  return resident * double(sysconf(_SC_PAGESIZE)) / (1 << 20);
}

TEST(BrickTable, CreateThenLookUp) {
  BrickTable table({5, 4, 3}, false);
  const Coord bc{4, 3, 2};
  EXPECT_EQ(table.idAt(bc), BrickTable::kNoBrick);  // no super-block yet
  EXPECT_EQ(table.brickAt(bc), nullptr);
  const uint32_t id = table.idOf(bc, true);
  ASSERT_NE(id, BrickTable::kNoBrick);
  EXPECT_EQ(table.idAt(bc), id);
  EXPECT_EQ(table.brickAt(bc), nullptr);  // the id exists, the brick not yet
  int64_t created = 0;
  BrickState* b = table.getOrCreate(id, &created);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(created, 1);
  EXPECT_EQ(table.getOrCreate(id, &created), b);
  EXPECT_EQ(created, 1);
  EXPECT_EQ(b->origin, (Coord{32, 24, 16}));
  EXPECT_EQ(table.originOf(id), b->origin);
  EXPECT_EQ(table.brickAt(bc), b);
  EXPECT_EQ(table.find({39, 31, 23}), b);
  EXPECT_EQ(table.find({31, 31, 23}), nullptr);
  for (int i = 0; i < kBrickVoxels; ++i) ASSERT_EQ(b->key[i].load(), kUntouched);
  EXPECT_EQ(b->expiry, nullptr);
  // Outside the grid: no id, with or without create.
  EXPECT_EQ(table.idOf({5, 0, 0}, true), BrickTable::kNoBrick);
  EXPECT_EQ(table.idOf({0, -1, 0}, true), BrickTable::kNoBrick);
  EXPECT_EQ(table.idAt({0, 0, 3}), BrickTable::kNoBrick);
  table.release(id);
  EXPECT_EQ(table.brickAt(bc), nullptr);
}

TEST(BrickTable, LifespanBricksStartNeverExpiring) {
  BrickTable table({1, 1, 1}, true);
  int64_t created = 0;
  BrickState* b = table.getOrCreate(table.idOf({0, 0, 0}, true), &created);
  ASSERT_NE(b->expiry, nullptr);
  EXPECT_EQ(b->expiry[0].load(), kNeverExpires);
  EXPECT_EQ(b->expiry[kBrickVoxels - 1].load(), kNeverExpires);
}

TEST(BrickTable, IdsAreDistinctAndOriginsRoundTrip) {
  BrickTable table({40, 20, 35}, false);  // several super-blocks per axis, partial ones at the far faces
  std::set<uint32_t> ids;
  for (int z = 0; z < 35; z += 3)
    for (int y = 0; y < 20; y += 2)
      for (int x = 0; x < 40; x += 3) {
        const uint32_t id = table.idOf({x, y, z}, true);
        ASSERT_TRUE(ids.insert(id).second) << x << "," << y << "," << z;
        ASSERT_EQ(table.originOf(id), (Coord{x * 8, y * 8, z * 8}));
      }
  EXPECT_EQ(table.blockCount(), size_t(3 * 2 * 3));
}

TEST(BrickTable, ConcurrentCreatorsGetOneBrick) {
  BrickTable table(kHugeBricks, false);
  const Coord bc{1000, 17, 2047};
  std::vector<BrickState*> got(20000, nullptr);
  std::atomic<int64_t> created{0};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, got.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      int64_t mine = 0;
      got[i] = table.getOrCreate(table.idOf(bc, true), &mine);  // the super-block is raced for too
      created += mine;
    }
  });
  EXPECT_EQ(created.load(), 1);
  EXPECT_EQ(table.blockCount(), 1u);
  for (BrickState* b : got) ASSERT_EQ(b, got[0]);
  EXPECT_EQ(table.brickAt(bc), got[0]);
  // Many bricks over a few super-blocks, each created by many threads at once: one brick per coordinate.
  std::vector<Coord> coords;
  for (int i = 0; i < 500; ++i) coords.push_back({(i * 37) % 48, (i * 11) % 40, 2000 + (i * 7) % 48});
  std::vector<BrickState*> many(20000, nullptr);
  created = 0;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, many.size(), 8), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      int64_t mine = 0;
      many[i] = table.getOrCreate(table.idOf(coords[i % coords.size()], true), &mine);
      created += mine;
    }
  });
  std::set<std::tuple<int, int, int>> distinct;
  for (const Coord& c : coords) distinct.insert({c.x, c.y, c.z});
  EXPECT_EQ(created.load(), int64_t(distinct.size()));
  for (size_t i = 0; i < many.size(); ++i) {
    const Coord& c = coords[i % coords.size()];
    ASSERT_EQ(many[i], table.brickAt(c));
    ASSERT_EQ(many[i]->origin, (Coord{c.x * 8, c.y * 8, c.z * 8}));
  }
}

TEST(BrickTable, NeighbourIdsAgreeWithTheMapAcrossSuperBlocks) {
  BrickTable table({40, 33, 17}, false);
  std::mt19937 rng(7);
  std::vector<Coord> probes = {{0, 0, 0}, {15, 15, 15}, {16, 16, 16}, {39, 32, 16}, {31, 15, 0}, {32, 16, 15}};
  for (int i = 0; i < 300; ++i) probes.push_back({int(rng() % 40), int(rng() % 33), int(rng() % 17)});
  for (const Coord& bc : probes) {
    const uint32_t id = table.idOf(bc, true);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Coord n{bc.x + dx, bc.y + dy, bc.z + dz};
          const uint32_t expect = table.idOf(n, true);
          ASSERT_EQ(table.neighbourId(id, bc, dx, dy, dz), expect) << bc.x << "," << bc.y << "," << bc.z;
          uint32_t got = 0;
          ASSERT_EQ(table.neighbourSlot(id, &table.slot(id), bc, dx, dy, dz, &got),
                    expect == BrickTable::kNoBrick ? nullptr : &table.slot(expect));
          ASSERT_EQ(got, expect);
        }
  }
}

TEST(BrickTable, BricksFromAgreesWithSingleLookups) {
  BrickTable table({40, 33, 17}, false);
  std::mt19937 rng(5);
  int64_t created = 0;
  for (int i = 0; i < 2000; ++i) {
    const Coord bc{int(rng() % 40), int(rng() % 33), int(rng() % 17)};
    table.getOrCreate(table.idOf(bc, true), &created);
  }
  std::vector<Coord> probes = {{-1, -1, -1}, {15, 15, 15}, {14, 14, 14}, {39, 32, 16}, {31, 0, 15}, {38, 31, 15}};
  for (int i = 0; i < 500; ++i) probes.push_back({int(rng() % 42) - 1, int(rng() % 35) - 1, int(rng() % 19) - 1});
  for (const Coord& b0 : probes) {
    BrickState* bricks[8];
    uint32_t ids[8];
    table.bricksFrom(b0, bricks, ids);
    for (int j = 0; j < 8; ++j) {
      const Coord bc{b0.x + (j & 1), b0.y + ((j >> 1) & 1), b0.z + (j >> 2)};
      ASSERT_EQ(bricks[j], table.brickAt(bc)) << bc.x << "," << bc.y << "," << bc.z;
      ASSERT_EQ(ids[j], table.idAt(bc)) << bc.x << "," << bc.y << "," << bc.z;
    }
  }
}

TEST(BrickTable, OriginKeyOrdersByZThenYThenX) {
  const std::vector<Coord> sorted = {{8, 0, 0}, {16376, 0, 0}, {0, 8, 0}, {16376, 16376, 0}, {0, 0, 8},
                                     {8, 0, 8}, {0, 16376, 8}, {0, 0, 16376}, {16376, 16376, 16376}};
  for (size_t i = 1; i < sorted.size(); ++i)
    EXPECT_LT(BrickTable::originKey(sorted[i - 1]), BrickTable::originKey(sorted[i])) << i;
}

TEST(BrickTable, FarApartBricksOnA16384GridCostOnlyWhatTheyTouch) {
  const double before = residentMb();
  BrickTable table(kHugeBricks, false);
  const Coord corners[] = {{0, 0, 0}, {2047, 2047, 2047}, {2047, 0, 1024}, {0, 2047, 0}};
  std::vector<BrickState*> bricks;
  int64_t created = 0;
  for (const Coord& bc : corners) bricks.push_back(table.getOrCreate(table.idOf(bc, true), &created));
  EXPECT_EQ(created, 4);
  for (size_t i = 0; i < std::size(corners); ++i) {
    EXPECT_EQ(table.brickAt(corners[i]), bricks[i]);
    EXPECT_EQ(bricks[i]->origin, (Coord{corners[i].x * 8, corners[i].y * 8, corners[i].z * 8}));
  }
  EXPECT_EQ(table.brickAt({1, 0, 0}), nullptr);
  EXPECT_EQ(table.brickAt({1024, 1024, 1024}), nullptr);
  EXPECT_EQ(table.blockCount(), 4u);
  EXPECT_LT(table.mapBytes(), size_t(1) << 20);
  // A dense table would be 64 GiB; the sparse one is a few pages per touched super-block.
  EXPECT_LT(residentMb() - before, 8.0);
  EXPECT_EQ(table.releaseAll(), 4u);
  EXPECT_EQ(table.brickAt(corners[1]), nullptr);
}

TEST(BrickPool, FreedStorageIsReusedAndStaysDistinct) {
  BrickPool pool;
  std::set<void*> live;
  std::vector<void*> order;
  for (int i = 0; i < 1500; ++i) {  // a few chunks
    void* p = pool.allocate();
    ASSERT_TRUE(live.insert(p).second);
    order.push_back(p);
  }
  pool.deallocate(order[700]);
  live.erase(order[700]);
  EXPECT_EQ(pool.allocate(), order[700]);  // the freed brick's storage comes back first
}

TEST(BrickPool, DrainingGivesEmptiedChunksBack) {
  const double before = residentMb();
  std::vector<void*> bricks;
  {
    BrickPool pool;
    for (int i = 0; i < 4000; ++i) bricks.push_back(new (pool.allocate()) BrickState({0, 0, 0}, false));  // ~17 MiB
    const double full = residentMb();
    EXPECT_GT(full - before, 12.0);
    pool.deallocate(bricks[0]);  // before draining: kept for reuse
    pool.drain();
    for (size_t i = 1; i < bricks.size(); ++i) {
      static_cast<BrickState*>(bricks[i])->~BrickState();
      pool.deallocate(bricks[i]);
    }
    // Every chunk emptied while draining is unmapped at once (the pool itself still exists).
    EXPECT_LT(residentMb() - before, 4.0);
  }
}

TEST(BrickTable, DrainedTableStillReleasesEveryBrick) {
  BrickTable table({16, 16, 16}, true);
  int64_t created = 0;
  std::vector<uint32_t> ids;
  for (int z = 0; z < 16; ++z)
    for (int x = 0; x < 16; ++x) ids.push_back(table.idOf({x, z % 4, z}, true));
  for (uint32_t id : ids) table.getOrCreate(id, &created);
  EXPECT_EQ(created, 256);
  table.drain();
  for (size_t i = 0; i < ids.size(); i += 2) table.release(ids[i]);
  EXPECT_EQ(table.get(ids[0]), nullptr);
  EXPECT_NE(table.get(ids[1]), nullptr);
  EXPECT_EQ(table.get(ids[1])->origin, table.originOf(ids[1]));
  EXPECT_EQ(table.releaseAll(), 128u);
}

}  // namespace
}  // namespace distband::band_internal
