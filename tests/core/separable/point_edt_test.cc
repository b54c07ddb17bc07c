// Tests for core/separable_points: the whole-grid field of point seeds against brute force (tests/support/brute_force,
// which shares no code with core/) and bit-identical to the band engine's values, for points off the lattice, on
// shared lines and planes, duplicated, outside the grid and far away; streamed under the engine's contract (segments,
// chunks), with closest features; identical for any thread count; a tile equal to the whole grid; stopped by its
// interrupter; its preconditions; the layout counts and its cost rule (the planner's use of it:
// tests/core/field/field_plan_test.cc).
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/seeds/point_seeds.h"
#include "core/separable/point_edt.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_force.h"
#include "tests/support/segment_collector.h"

namespace distband {
namespace {

CollectedField runSeparable(const Grid& grid, const Seeds& seeds, const BandOptions& o) {
  return collectSegments(grid, o, [&](const SegmentCallback& cb) { return computeSeparablePointField(grid, seeds, o, cb); });
}

CollectedField runBand(const Grid& grid, const Seeds& seeds, const BandOptions& o) {
  return collectSegments(grid, o, [&](const SegmentCallback& cb) { return computeBandField(grid, seeds, o, cb); });
}

// Points meant to break a careless separable pass: off-lattice, several on one line and one plane, a duplicate,
// points outside the grid on every side, one far away, and exact ties.
std::vector<Vec3d> awkwardPoints(uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-6, 40);
  std::vector<Vec3d> p;
  for (int i = 0; i < 5; ++i) p.push_back({u(rng), u(rng), u(rng)});
  p.push_back({3.25, 7.5, 11.0});  // one line (y, z) = (7.5, 11) ...
  p.push_back({19.75, 7.5, 11.0});
  p.push_back({30.0, 7.5, 11.0});
  p.push_back({12.0, 20.25, 11.0});  // ... in a plane with another line
  p.push_back({19.75, 7.5, 11.0});   // a duplicate
  p.push_back({-30.0, 2.0, 5.0});    // outside the grid
  p.push_back({5.0, 60.0, -12.5});
  p.push_back({10.0, 10.0, 1.0e7});  // far away: its plane must not spoil the envelope's arithmetic
  p.push_back({14.0, 16.0, 22.0});   // a tie: voxels on the plane x = 16 are equally near both
  p.push_back({18.0, 16.0, 22.0});
  return p;
}

TEST(SeparablePointsTest, MatchesBruteForceAndTheBandBitForBitWithSegmentsChunksAndClosestPoints) {
  const Coord d{37, 29, 26};  // not multiples of 8: partial bricks on the far faces
  const Grid grid({1, -2, 0.5}, 0.5, d);
  for (uint64_t seed : {1, 2, 3}) {
    std::vector<Vec3d> index_points = awkwardPoints(seed), world;
    for (const Vec3d& p : index_points) world.push_back({1 + 0.5 * p.x, -2 + 0.5 * p.y, 0.5 + 0.5 * p.z});
    Seeds seeds;
    ASSERT_TRUE(IsOk(makePointSeeds(grid, world, &seeds)));
    std::vector<std::array<double, 3>> plain;
    for (const Vec3d& p : seeds.points) plain.push_back({p.x, p.y, p.z});
    const std::vector<double> exact2 = oracle::bruteForceDistanceSqr(d.x, d.y, d.z, plain);
    BandOptions o;
    o.segment_length_world = seed == 1 ? 0 : 2.5;
    o.max_chunk_bricks = seed == 3 ? 7 : 0;
    o.closest_features = true;
    const CollectedField c = runSeparable(grid, seeds, o);
    const CollectedField band = runBand(grid, seeds, o);
    EXPECT_EQ(c.order_error, "") << seed;
    EXPECT_FALSE(c.result.interrupted);
    EXPECT_EQ(c.result.voxels, grid.voxelCount());
    int64_t wrong = 0, not_once = 0, wrong_closest = 0, unlike_band = 0;
    for (size_t i = 0; i < exact2.size(); ++i) {
      not_once += c.times_delivered[i] != 1;
      wrong += std::abs(double(c.values[i]) - std::sqrt(exact2[i]) * 0.5) > 1e-6 * (1 + std::sqrt(exact2[i]));
      unlike_band += std::memcmp(&c.values[i], &band.values[i], sizeof(float)) != 0;
      // The closest point is one at the voxel's distance (ties: either).
      const Vec3d v{double(i % d.x), double(i / d.x % d.y), double(i / (size_t(d.x) * d.y))};
      const int64_t id = c.closest[i];
      wrong_closest += id < 0 || size_t(id) >= seeds.points.size() ||
                       std::abs((v - seeds.points[size_t(id)]).lengthSqr() - exact2[i]) > 1e-9 * (1 + exact2[i]);
    }
    EXPECT_EQ(not_once, 0) << seed;
    EXPECT_EQ(wrong, 0) << seed;
    EXPECT_EQ(unlike_band, 0) << seed;
    EXPECT_EQ(wrong_closest, 0) << seed;
  }
}

// Anisotropic voxels: world distances against brute force with the same spacing, and bit for bit the band's values.
TEST(SeparablePointsTest, OnAnisotropicVoxelsMatchesBruteForceAndTheBand) {
  const Coord d{33, 27, 19};
  const Vec3d spacing{0.5, 0.75, 2.0};
  const Grid grid({1, -2, 0.5}, spacing, d);
  std::vector<Vec3d> world;
  std::vector<std::array<double, 3>> index;
  for (const Vec3d& p : awkwardPoints(4)) {
    world.push_back({1 + spacing.x * p.x, -2 + spacing.y * p.y, 0.5 + spacing.z * p.z});
    index.push_back({p.x, p.y, p.z});
  }
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, world, &seeds)));
  const std::vector<double> exact2 =
      oracle::bruteForceDistanceSqr(d.x, d.y, d.z, index, {spacing.x, spacing.y, spacing.z});
  BandOptions o;
  o.segment_length_world = 3;
  o.closest_features = true;
  const CollectedField c = runSeparable(grid, seeds, o);
  const CollectedField band = runBand(grid, seeds, o);
  EXPECT_EQ(c.order_error, "");
  int64_t wrong = 0, not_once = 0, unlike_band = 0;
  for (size_t i = 0; i < exact2.size(); ++i) {
    not_once += c.times_delivered[i] != 1;
    wrong += std::abs(double(c.values[i]) - std::sqrt(exact2[i])) > 1e-6 * (1 + std::sqrt(exact2[i]));
    unlike_band += std::memcmp(&c.values[i], &band.values[i], sizeof(float)) != 0;
  }
  EXPECT_EQ(not_once, 0);
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(unlike_band, 0);
}

TEST(SeparablePointsTest, IdenticalForAnyThreadCountEqualOnATileAndStoppedByItsInterrupter) {
  const Coord d{70, 52, 41};
  const Grid grid({0, 0, 0}, 1, d);
  std::vector<Vec3d> points = awkwardPoints(7);
  points.resize(9);
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, points, &seeds)));
  BandOptions o;
  o.segment_length_world = 6;
  o.threads = 1;
  const CollectedField one = runSeparable(grid, seeds, o);
  o.threads = 2;
  const CollectedField two = runSeparable(grid, seeds, o);
  ASSERT_EQ(one.result.voxels, grid.voxelCount());
  EXPECT_EQ(std::memcmp(one.values.data(), two.values.data(), one.values.size() * sizeof(float)), 0);
  // A tile: the window's values equal the whole grid's there.
  const VoxelBox window{{13, 8, 5}, {40, 30, 20}};
  Seeds tile_seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, points, &tile_seeds, &window)));
  const Grid tile = grid.window(window);
  const CollectedField t = runSeparable(tile, tile_seeds, o);
  int64_t differ = 0;
  for (int z = 0; z < window.dims.z; ++z)
    for (int y = 0; y < window.dims.y; ++y)
      for (int x = 0; x < window.dims.x; ++x) {
        const float a = t.values[size_t(tile.denseIndex({x, y, z}))];
        const float b = one.values[size_t(grid.denseIndex(window.min + Coord{x, y, z}))];
        differ += std::memcmp(&a, &b, sizeof(float)) != 0;
      }
  EXPECT_EQ(differ, 0);
  Interrupter stop;
  stop.cancel(Status::Code::kCancelled, "test");
  o.interrupter = &stop;
  const CollectedField stopped = runSeparable(grid, seeds, o);
  EXPECT_TRUE(stopped.result.interrupted);
  EXPECT_EQ(stopped.result.voxels, 0);
}

TEST(SeparablePointsTest, RejectsWhatItCannotCompute) {
  const Grid grid({0, 0, 0}, 1, {16, 16, 16});
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, {{3, 4, 5}}, &seeds)));
  BandOptions limited;
  limited.limit_world = 5;
  EXPECT_THROW(computeSeparablePointField(grid, seeds, limited, {}), std::invalid_argument);
  Seeds none = seeds;
  none.points.clear();
  EXPECT_THROW(computeSeparablePointField(grid, none, {}, {}), std::invalid_argument);
  Seeds triangles = seeds;
  triangles.kind = SiteKind::kTriangle;
  EXPECT_THROW(computeSeparablePointField(grid, triangles, {}, {}), std::invalid_argument);
}

TEST(SeparablePointsTest, PointsBeyondDoubleRangeAreInfinitelyFarAsInTheBand) {
  const Grid grid({0, 0, 0}, 1, {20, 17, 12});
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, {{3, 4, 5}, {0, 0, 11}, {9.5, 2, 7}}, &seeds)));
  // What indexOf makes of a world coordinate near 1e308 on a voxel size of 1e-300; the point's band voxels stay where
  // makePointSeeds clamped them.
  const double inf = std::numeric_limits<double>::infinity();
  seeds.points[1] = {inf, 4, -inf};
  for (int all_infinite = 0; all_infinite < 2; ++all_infinite) {
    if (all_infinite) seeds.points = {{inf, 1, 2}, {3, -inf, 2}, {3, 1, inf}};
    const CollectedField separable = runSeparable(grid, seeds, {});
    const CollectedField band = runBand(grid, seeds, {});
    ASSERT_EQ(separable.result.voxels, grid.voxelCount());
    EXPECT_EQ(std::memcmp(separable.values.data(), band.values.data(), band.values.size() * sizeof(float)), 0);
    EXPECT_EQ(std::isinf(separable.values[0]), bool(all_infinite));
  }
}

TEST(SeparablePointsTest, LayoutCountsLinesAndPlanesAndItPaysOnFewPlanes) {
  const PointLayout l = pointLayout({{1, 2, 3}, {5, 2, 3}, {1, 4, 3}, {1, 2, 9}, {1, 2, 3}});
  EXPECT_EQ(l.points, 5);
  EXPECT_EQ(l.lines, 3);   // (2, 3), (4, 3), (2, 9)
  EXPECT_EQ(l.planes, 2);  // 3, 9
  const Coord dims{64, 64, 64};
  EXPECT_TRUE(separablePointsPay(dims, l));
  EXPECT_TRUE(separablePointsPay(dims, {100, 100, 14}));   // 100 + 64 * 14 <= 64 * 64 / 4
  EXPECT_FALSE(separablePointsPay(dims, {100, 100, 15}));  // a point cloud spread over many planes: the band
  EXPECT_TRUE(separablePointsPay(dims, {900, 900, 1}));
  EXPECT_FALSE(separablePointsPay(dims, {1000, 1000, 1}));  // too many lines
}

}  // namespace
}  // namespace distband
