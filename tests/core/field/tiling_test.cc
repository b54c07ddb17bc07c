// Tests for core/tiling (tile plans cover the grid exactly once, in whole bricks, windows hold the halo) and for
// windowed point seeds (Seeds::site_offset): a tile computed on its window alone gives the whole grid's values,
// bit for bit, inside the part it delivers.
#include "core/field/tiling.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/io/dense_field.h"
#include "core/band/band_engine.h"
#include "core/seeds/point_seeds.h"
#include "core/status.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

void expectCoversOnce(const Coord& dims, const std::vector<TilePlan>& tiles) {
  std::vector<int> hits(size_t(dims.x) * dims.y * dims.z, 0);
  for (const TilePlan& t : tiles) {
    EXPECT_EQ(t.deliver.min.x % kBrickSize, 0);
    EXPECT_EQ(t.deliver.min.y % kBrickSize, 0);
    EXPECT_EQ(t.deliver.min.z % kBrickSize, 0);
    EXPECT_EQ(t.window.min.x % kBrickSize, 0);
    EXPECT_TRUE(t.window.contains(t.deliver));
    EXPECT_TRUE((VoxelBox{{}, dims}).contains(t.window));
    for (int z = t.deliver.min.z; z < t.deliver.end().z; ++z)
      for (int y = t.deliver.min.y; y < t.deliver.end().y; ++y)
        for (int x = t.deliver.min.x; x < t.deliver.end().x; ++x) ++hits[(size_t(z) * dims.y + y) * dims.x + x];
  }
  for (int h : hits) ASSERT_EQ(h, 1);
}

TEST(TilingTest, TilesCoverTheGridOnceInWholeBricks) {
  for (const Coord dims : {Coord{100, 37, 64}, Coord{8, 8, 8}, Coord{1, 300, 17}, Coord{129, 129, 129}}) {
    const auto tiles = planTiles(dims, 32 * 32 * 32, 5);
    expectCoversOnce(dims, tiles);
    for (const TilePlan& t : tiles) EXPECT_LE(t.deliver.voxelCount(), 32 * 32 * 32);
  }
}

TEST(TilingTest, SmallGridsAreOneTileAndTilesAreNearCubes) {
  EXPECT_EQ(planTiles({50, 50, 50}, 1 << 20, 3).size(), 1u);
  const auto tiles = planTiles({256, 256, 256}, 64 * 64 * 64, 3);
  ASSERT_EQ(tiles.size(), 64u);
  EXPECT_EQ(tiles[0].deliver.dims, (Coord{64, 64, 64}));
  EXPECT_EQ(tiles[1].deliver.min, (Coord{64, 0, 0}));  // x fastest
}

TEST(TilingTest, WindowsGrowByTheHaloInWholeBricksClippedToTheGrid) {
  const auto tiles = planTiles({256, 256, 256}, 64 * 64 * 64, 5);
  const TilePlan& inner = tiles[1 + 4 + 16];  // deliver [64, 128) on every axis
  ASSERT_EQ(inner.deliver.min, (Coord{64, 64, 64}));
  EXPECT_EQ(inner.window.min, (Coord{56, 56, 56}));   // 64 - 5 rounded down to a brick
  EXPECT_EQ(inner.window.end(), (Coord{136, 136, 136}));  // 128 + 5 rounded up
  EXPECT_EQ(tiles[0].window.min, (Coord{0, 0, 0}));
  for (const TilePlan& t : planTiles({256, 256, 256}, 64 * 64 * 64, -1)) EXPECT_EQ(t.window, (VoxelBox{{}, {256, 256, 256}}));
  EXPECT_EQ(tileHalo(std::numeric_limits<double>::infinity()), -1);
  EXPECT_EQ(tileHalo(4.2), 5 + 16);
}

TEST(TilingTest, TileCountIsBounded) {
  const auto tiles = planTiles({16384, 16384, 64}, 1, 0);
  EXPECT_LE(tiles.size(), kMaxTiles);
  expectCoversOnce({64, 64, 64}, planTiles({64, 64, 64}, 1, 0));
}

DenseField computeDense(const Grid& grid, Seeds seeds, double limit) {
  BandOptions o;
  o.limit_world = limit;
  DenseField field(grid, -1.0f);
  const FieldRunResult r = computeBandField(grid, std::move(seeds), o, [&](SegmentBricks&& s) { field.add(s); });
  EXPECT_FALSE(r.interrupted);
  return field;
}

TEST(TilingTest, WindowedPointSeedsAreBitIdenticalToTheWholeGrid) {
  const Grid grid({-1.3, 0.7, 2.1}, 0.37, {70, 61, 53});
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 27.0);
  std::vector<Vec3d> points;
  for (int i = 0; i < 40; ++i) points.push_back({u(rng), u(rng), u(rng) * 0.8});
  points.push_back({-20.0, 5.0, 5.0});  // far outside the grid
  for (double limit : {2.0, std::numeric_limits<double>::infinity()}) {
    Seeds whole_seeds;
    ASSERT_TRUE(IsOk(makePointSeeds(grid, points, &whole_seeds)));
    const DenseField whole = computeDense(grid, std::move(whole_seeds), limit);
    const auto tiles = planTiles(grid.dims(), 24 * 24 * 24, std::isfinite(limit) ? tileHalo(limit / grid.voxelSize()) : 16);
    ASSERT_GT(tiles.size(), 4u);
    int64_t compared = 0;
    for (const TilePlan& t : tiles) {
      Seeds seeds;
      ASSERT_TRUE(IsOk(makePointSeeds(grid, points, &seeds, &t.window)));
      EXPECT_EQ(seeds.site_offset, t.window.min);
      const DenseField part = computeDense(grid.window(t.window), std::move(seeds), limit);
      for (int z = t.deliver.min.z; z < t.deliver.end().z; ++z)
        for (int y = t.deliver.min.y; y < t.deliver.end().y; ++y)
          for (int x = t.deliver.min.x; x < t.deliver.end().x; ++x) {
            const Coord local{x - t.window.min.x, y - t.window.min.y, z - t.window.min.z};
            ASSERT_EQ(part.at(local), whole.at({x, y, z})) << "limit " << limit << " voxel " << x << "," << y << "," << z;
            ++compared;
          }
    }
    EXPECT_EQ(compared, grid.voxelCount());
  }
}

}  // namespace
}  // namespace distband
