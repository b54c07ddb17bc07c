// Tests for core/separable_edt: the whole-grid volume field against the exact EDT oracle (tests/support/exact_edt,
// which shares no code with core/), streamed under the band engine's contract (segments nearest first, each voxel
// once, bricks sorted, chunks), identical for any thread count, stopped by its interrupter. The planner's choice of
// it: tests/core/field/field_plan_test.cc.
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "core/separable/volume_edt.h"
#include "tests/support/exact_edt.h"
#include "tests/support/segment_collector.h"

namespace distband {
namespace {

std::vector<uint8_t> randomBlobs(const Coord& d, int count, uint64_t seed) {
  std::vector<uint8_t> mask(size_t(d.x) * d.y * d.z, 0);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(0, d.x), uy(0, d.y), uz(0, d.z), ur(1, 6);
  for (int i = 0; i < count; ++i) {
    const double cx = ux(rng), cy = uy(rng), cz = uz(rng), r = ur(rng);
    for (int z = 0; z < d.z; ++z)
      for (int y = 0; y < d.y; ++y)
        for (int x = 0; x < d.x; ++x)
          if ((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) <= r * r)
            mask[(size_t(z) * d.y + y) * d.x + x] = 1;
  }
  return mask;
}

using Collected = CollectedField;

Collected run(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative, const BandOptions& o) {
  return collectSegments(grid, o, [&](const SegmentCallback& on_segment) {
    return computeSeparableVolumeField(grid, mask, inside_negative, o, on_segment);
  });
}

TEST(SeparableEdtTest, MatchesTheExactEdtUnsignedAndSignedWithSegmentsAndChunks) {
  const Coord d{45, 38, 29};  // not multiples of 8: partial bricks on the far faces
  const Grid grid({1, -2, 0.5}, 0.5, d);
  const std::vector<uint8_t> mask = randomBlobs(d, 6, 11);
  const std::vector<double> exact2 = oracle::edtSqr(d.x, d.y, d.z, mask);
  const std::vector<double> signed_exact = oracle::signedEdt(d.x, d.y, d.z, mask);
  for (bool inside_negative : {false, true})
    for (double segment : {0.0, 1.0, 3.7}) {
      BandOptions o;
      o.segment_length_world = segment;
      o.max_chunk_bricks = segment == 1.0 ? 7 : 0;
      const Collected c = run(grid, mask, inside_negative, o);
      EXPECT_EQ(c.order_error, "") << inside_negative << " " << segment;
      int64_t wrong = 0, missing = 0;
      for (size_t i = 0; i < c.values.size(); ++i) {
        missing += c.times_delivered[i] != 1;
        const double want = 0.5 * (inside_negative ? signed_exact[i] : std::sqrt(exact2[i]));
        wrong += std::abs(c.values[i] - want) > 1e-5;
      }
      EXPECT_EQ(missing, 0) << "every voxel exactly once";
      EXPECT_EQ(wrong, 0) << inside_negative << " " << segment;
      EXPECT_EQ(c.result.voxels, grid.voxelCount());
      if (segment > 0) {
        EXPECT_GT(c.result.segments.size(), 3u);
      }
    }
}

// Runs `o` at 1 and 2 threads (bit-identical, undelivered voxels included) and stopped before it starts.
void expectIdenticalForAnyThreadCountAndStoppable(const Grid& grid, const std::vector<uint8_t>& mask, BandOptions o,
                                                  int64_t min_voxels) {
  o.threads = 1;
  const Collected one = run(grid, mask, true, o);
  o.threads = 2;
  const Collected two = run(grid, mask, true, o);
  EXPECT_GT(one.result.voxels, min_voxels);
  EXPECT_EQ(std::memcmp(one.values.data(), two.values.data(), one.values.size() * sizeof(float)), 0);
  Interrupter stop;
  stop.cancel(Status::Code::kCancelled, "test");
  o.interrupter = &stop;
  const Collected stopped = run(grid, mask, false, o);
  EXPECT_TRUE(stopped.result.interrupted);
  EXPECT_EQ(stopped.result.voxels, 0);
}

TEST(SeparableEdtTest, IdenticalForAnyThreadCountAndStoppedByItsInterrupter) {
  const Coord d{64, 64, 64};
  const Grid grid({0, 0, 0}, 1, d);
  BandOptions o;
  o.segment_length_world = 4;
  expectIdenticalForAnyThreadCountAndStoppable(grid, randomBlobs(d, 10, 3), o, 64 * 64 * 64 - 1);
}

// Blobs plus a solid box: whole bricks inside the mask, whole bricks outside beside them, and blobs cut by the faces.
std::vector<uint8_t> blobsAndBox(const Coord& d, uint64_t seed) {
  std::vector<uint8_t> mask = randomBlobs(d, 8, seed);
  for (int z = 3; z < 30 && z < d.z; ++z)
    for (int y = 9; y < 41 && y < d.y; ++y)
      for (int x = 0; x < 26 && x < d.x; ++x) mask[(size_t(z) * d.y + y) * d.x + x] = 1;
  return mask;
}

TEST(SeparableEdtTest, WithALimitDeliversExactlyTheVoxelsWithinIt) {
  const Coord d{53, 47, 38};
  const Grid grid({0, 0, 0}, 0.25, d);
  const std::vector<uint8_t> mask = blobsAndBox(d, 5);
  const std::vector<double> exact2 = oracle::edtSqr(d.x, d.y, d.z, mask);
  const std::vector<double> signed_exact = oracle::signedEdt(d.x, d.y, d.z, mask);
  // Limits in voxels; squares that are not integers, so no voxel sits on the limit. 9.7 reaches two bricks away;
  // 20.5 takes the parabola envelope instead of the window minimum.
  for (double limit : {0.7, 1.5, 3.3, 5.5, 9.7, 20.5})
    for (bool inside_negative : {false, true})
      for (double segment : {0.0, 0.3}) {
        BandOptions o;
        o.limit_world = limit * 0.25;
        o.segment_length_world = segment;
        o.max_chunk_bricks = segment > 0 ? 5 : 0;
        const Collected c = run(grid, mask, inside_negative, o);
        const std::string where = fmt::format("limit {} signed {} segment {}", limit, inside_negative, segment);
        EXPECT_EQ(c.order_error, "") << where;
        int64_t wrong = 0, missing = 0, extra = 0, within = 0;
        for (size_t i = 0; i < c.values.size(); ++i) {
          const double want = inside_negative ? signed_exact[i] : std::sqrt(exact2[i]);
          if (std::abs(want) > limit) {
            extra += c.times_delivered[i] != 0;
            continue;
          }
          ++within;
          missing += c.times_delivered[i] != 1;
          wrong += c.times_delivered[i] == 1 && std::abs(c.values[i] - 0.25 * want) > 1e-6;
        }
        EXPECT_EQ(missing, 0) << where;
        EXPECT_EQ(extra, 0) << where << ": delivered beyond the limit";
        EXPECT_EQ(wrong, 0) << where;
        EXPECT_EQ(c.result.voxels, within) << where;
        for (const SegmentStats& s : c.result.segments) EXPECT_LE(s.upper_world, o.limit_world) << where;
      }
}

TEST(SeparableEdtTest, WithALimitTheWorkFollowsTheBand) {
  // One small ball in a 256^3 grid (32768 bricks): the passes visit the bricks near it, not the grid.
  const Coord d{256, 256, 256};
  const Grid grid({0, 0, 0}, 1, d);
  std::vector<uint8_t> mask(size_t(grid.voxelCount()), 0);
  for (int z = 120; z < 126; ++z)
    for (int y = 60; y < 66; ++y)
      for (int x = 200; x < 206; ++x) mask[(size_t(z) * d.y + y) * d.x + x] = 1;
  for (double limit : {3.5, 12.5}) {
    BandOptions o;
    o.limit_world = limit;
    const Collected c = run(grid, mask, false, o);
    EXPECT_EQ(c.order_error, "");
    // The ball's box grown by the limit spans at most 4 (3.5) or 6 (12.5) bricks a side.
    const int64_t side = limit < 8 ? 4 : 6;
    EXPECT_LE(c.result.bricks_allocated, side * side * side) << limit;
    EXPECT_GT(c.result.voxels, 200) << limit;
  }
}

TEST(SeparableEdtTest, WithALimitIdenticalForAnyThreadCountAndStoppable) {
  const Coord d{96, 80, 72};
  BandOptions o;
  o.limit_world = 6.5;
  o.segment_length_world = 2;
  expectIdenticalForAnyThreadCountAndStoppable(Grid({0, 0, 0}, 1, d), blobsAndBox(d, 9), o, 10000);
}

TEST(SeparableEdtTest, RejectsMasksItCannotMeasure) {
  const Grid grid({0, 0, 0}, 1, {8, 8, 8});
  EXPECT_THROW(computeSeparableVolumeField(grid, std::vector<uint8_t>(512, 0), false, {}, {}), std::invalid_argument);
  EXPECT_THROW(computeSeparableVolumeField(grid, std::vector<uint8_t>(512, 1), true, {}, {}), std::invalid_argument);
  EXPECT_THROW(computeSeparableVolumeField(grid, std::vector<uint8_t>(100, 1), false, {}, {}), std::invalid_argument);
}

}  // namespace
}  // namespace distband
