// Tests for core/separable/volume_edt: the seed field against the exact EDT oracle (tests/support/exact_edt, which
// shares no code with core/), cubic and with per-axis spacing, for every element type; the multi-label EDT and the
// nearest labels against brute force (tests/support/brute_force); streamed under the band engine's contract (segments
// nearest first, each voxel once, bricks sorted, chunks), identical for any thread count, stopped by its interrupter.
// The planner's choice of it: tests/core/field/field_plan_test.cc.
#include <array>
#include <cmath>
#include <limits>
#include <cstring>
#include <random>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "core/separable/volume_edt.h"
#include "tests/support/brute_force.h"
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

Collected run(const Grid& grid, const LabelVolume& volume, const VolumeMeasure& measure, const BandOptions& o) {
  return collectSegments(grid, o, [&](const SegmentCallback& on_segment) {
    return computeSeparableVolumeField(grid, volume, measure, o, on_segment);
  });
}

Collected run(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative, const BandOptions& o) {
  return run(grid, LabelVolume::ofMask(grid.dims(), mask), {false, inside_negative, false}, o);
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
  // 20.5 takes the parabola envelope instead of the window minimum; 40.5 reaches four times a 0.3-segment's bricks,
  // so its first segment comes from a band of its own (near field first).
  // With chunks the band comes in two parts along z (near field first).
  for (double limit : {0.7, 1.5, 3.3, 5.5, 9.7, 20.5, 40.5})
    for (bool inside_negative : {false, true})
      for (double segment : {0.0, 0.3})
        for (size_t chunk : {0, 5}) {
          BandOptions o;
          o.limit_world = limit * 0.25;
          o.segment_length_world = segment;
          o.max_chunk_bricks = chunk;
          const Collected c = run(grid, mask, inside_negative, o);
          const std::string where =
              fmt::format("limit {} signed {} segment {} chunk {}", limit, inside_negative, segment, chunk);
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

// Near field first. Without a limit, with several segments, the first one is computed by the band within its bound
// and streamed before the whole grid: stopped when segment 0 is complete, a run has built only that band (the whole
// grid allocates no bricks). With a limit and chunks, the band comes in two parts along z and the first part's
// segment 0 is streamed before the rest is computed: stopped at the first chunk, a run has built a small part of the
// limit's band. With a limit and no chunks, a limit of 40 voxels (5 bricks) against 2-voxel segments (1 brick) takes
// the first segment's band, the smaller one; a limit of 10 voxels (2 bricks), where the first segment's band costs
// nearly the limit's, is computed once.
TEST(SeparableEdtTest, NearFieldFirstTheFirstSegmentComesBeforeTheRestIsComputed) {
  const Coord d{64, 56, 160};  // 20 layers of bricks along z
  const Grid grid({0, 0, 0}, 1, d);
  const std::vector<uint8_t> mask = randomBlobs(d, 12, 21);
  const LabelVolume volume = LabelVolume::ofMask(d, mask);
  // Runs `o` until `stop_when` says so: the bricks allocated then.
  auto stoppedWhen = [&](BandOptions o, const std::function<bool(const SegmentBricks&)>& stop_when) {
    Interrupter stop;
    o.interrupter = &stop;
    const FieldRunResult r = computeSeparableVolumeField(grid, volume, {false, true, false}, o, [&](SegmentBricks&& s) {
      if (stop_when(s)) stop.cancel(Status::Code::kCancelled, "test");
    });
    EXPECT_TRUE(r.interrupted);
    return r.bricks_allocated;
  };
  auto segment0Complete = [](const SegmentBricks& s) { return s.index == 0 && s.complete; };
  auto firstChunk = [](const SegmentBricks& s) {
    EXPECT_EQ(s.index, 0);
    EXPECT_FALSE(s.bricks.empty()) << "the first chunk holds bricks";
    return true;
  };
  BandOptions o;
  o.segment_length_world = 2;
  o.max_chunk_bricks = 16;
  EXPECT_GT(stoppedWhen(o, segment0Complete), 0) << "segment 0 came from a band, before the whole grid";
  for (double limit : {10.0, 40.0}) {
    BandOptions once = o;
    once.limit_world = limit;
    once.segment_length_world = 0;
    once.max_chunk_bricks = 0;
    const int64_t band = run(grid, mask, true, once).result.bricks_allocated;
    BandOptions chunked = o;
    chunked.limit_world = limit;
    const int64_t first_part = stoppedWhen(chunked, firstChunk);
    EXPECT_GT(first_part, 0) << limit;
    EXPECT_LT(first_part, band / 4) << limit;
    // Run to the end, both count the limit's band (the two parts' bricks, or the last band computed).
    EXPECT_EQ(run(grid, mask, true, chunked).result.bricks_allocated, band) << limit;
    BandOptions whole_segments = chunked;
    whole_segments.max_chunk_bricks = 0;
    EXPECT_EQ(run(grid, mask, true, whole_segments).result.bricks_allocated, band) << limit;
    const int64_t unchunked = stoppedWhen(whole_segments, segment0Complete);
    if (limit == 40) {
      EXPECT_LT(unchunked, band / 2) << "the first segment's band";
    } else {
      EXPECT_EQ(unchunked, band) << "computed once";
    }
  }
}

// Near field first when every voxel lies in segment 0: the second part has nothing, so an empty segment 1 ends the
// stream (marked last); every voxel still comes once, exact.
TEST(SeparableEdtTest, NearFieldFirstEndsWithAnEmptySegmentWhenSegmentZeroHoldsAll) {
  const Coord d{20, 17, 12};
  const Grid grid({0, 0, 0}, 1, d);
  std::vector<uint8_t> mask(size_t(grid.voxelCount()), 1);
  mask[(size_t(6) * d.y + 8) * d.x + 10] = 0;  // one non-seed voxel, at distance 1
  BandOptions o;
  o.segment_length_world = 3;
  const Collected c = run(grid, mask, false, o);
  EXPECT_EQ(c.order_error, "");
  ASSERT_EQ(c.result.segments.size(), 2u);
  EXPECT_EQ(c.result.segments[1].voxels, 0);
  EXPECT_EQ(c.result.voxels, grid.voxelCount());
  for (size_t i = 0; i < c.values.size(); ++i) {
    ASSERT_EQ(c.times_delivered[i], 1) << i;
    EXPECT_EQ(c.values[i], mask[i] ? 0.0f : 1.0f) << i;
  }
}

TEST(SeparableEdtTest, WithALimitIdenticalForAnyThreadCountAndStoppable) {
  const Coord d{96, 80, 72};
  BandOptions o;
  o.limit_world = 6.5;
  o.segment_length_world = 2;
  expectIdenticalForAnyThreadCountAndStoppable(Grid({0, 0, 0}, 1, d), blobsAndBox(d, 9), o, 10000);
}

TEST(SeparableEdtTest, RejectsVolumesItCannotMeasure) {
  const Grid grid({0, 0, 0}, 1, {8, 8, 8});
  auto mask = [](size_t n, uint8_t fill) { return LabelVolume::ofMask({int(n), 1, 1}, std::vector<uint8_t>(n, fill)); };
  auto cube = [](uint8_t fill) { return LabelVolume::ofMask({8, 8, 8}, std::vector<uint8_t>(512, fill)); };
  EXPECT_THROW(computeSeparableVolumeField(grid, cube(0), {}, {}, {}), std::invalid_argument);
  EXPECT_THROW(computeSeparableVolumeField(grid, cube(1), {false, true, false}, {}, {}), std::invalid_argument);
  EXPECT_THROW(computeSeparableVolumeField(grid, mask(100, 1), {}, {}, {}), std::invalid_argument);
  EXPECT_THROW(computeSeparableVolumeField(grid, cube(3), {true, false, 0}, {}, {}), std::invalid_argument);
  FieldRunOptions closest;
  closest.closest_features = true;
  EXPECT_THROW(computeSeparableVolumeField(grid, cube(3), {true, false, kAllFaces}, closest, {}),
               std::invalid_argument);
  EXPECT_NO_THROW(computeSeparableVolumeField(grid, cube(3), {true, false, kAllFaces}, {}, {}));
}

// ---- Anisotropic voxels, label volumes, the multi-label EDT and nearest labels ----

/// Blobs labelled 1..count (later ones over earlier ones), background 0.
std::vector<uint32_t> labelBlobs(const Coord& d, int count, double r_min, double r_max, uint64_t seed) {
  std::vector<uint32_t> labels(size_t(d.x) * d.y * d.z, 0);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(0, d.x), uy(0, d.y), uz(0, d.z), ur(r_min, r_max);
  for (int i = 0; i < count; ++i) {
    const double cx = ux(rng), cy = uy(rng), cz = uz(rng), r = ur(rng);
    for (int z = 0; z < d.z; ++z)
      for (int y = 0; y < d.y; ++y)
        for (int x = 0; x < d.x; ++x)
          if ((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) <= r * r)
            labels[(size_t(z) * d.y + y) * d.x + x] = uint32_t(i + 1);
  }
  return labels;
}

LabelVolume asVolume(const Coord& d, const std::vector<uint32_t>& labels, VoxelType type) {
  const size_t w = voxelTypeBytes(type);
  auto bytes = std::make_shared<std::vector<uint8_t>>(labels.size() * w);
  for (size_t i = 0; i < labels.size(); ++i) std::memcpy(bytes->data() + i * w, &labels[i], w);  // little-endian
  return LabelVolume(d, type, bytes);
}

std::array<double, 3> spacingOf(const Grid& g) { return {g.spacing().x, g.spacing().y, g.spacing().z}; }

// The seed field on anisotropic voxels, whole grid and within limits, signed and unsigned, against the exact EDT with
// the same spacing (scipy's `sampling`), for every element type.
TEST(SeparableEdtTest, AnisotropicSeedFieldMatchesTheExactEdtWithSpacing) {
  const Coord d{37, 30, 21};
  const Grid grid({1, -2, 0.5}, Vec3d{0.5, 0.5, 2.5}, d);
  const std::vector<uint32_t> labels = labelBlobs(d, 7, 1.5, 6, 5);
  std::vector<uint8_t> mask(labels.size());
  for (size_t i = 0; i < labels.size(); ++i) mask[i] = labels[i] != 0;
  const double spacing[3] = {0.5, 0.5, 2.5};
  const std::vector<double> exact2 = oracle::edtSqr(d.x, d.y, d.z, mask, spacing);
  const std::vector<double> signed_exact = oracle::signedEdt(d.x, d.y, d.z, mask, spacing);
  for (VoxelType type : kVoxelTypes)
    for (double limit : {std::numeric_limits<double>::infinity(), 1.3, 4.9})
      for (bool inside_negative : {false, true}) {
        BandOptions o;
        o.limit_world = limit;
        o.segment_length_world = 1.1;
        o.max_chunk_bricks = 9;
        const Collected c = run(grid, asVolume(d, labels, type), {false, inside_negative, false}, o);
        const std::string where = fmt::format("{} limit {} signed {}", voxelTypeName(type), limit, inside_negative);
        EXPECT_EQ(c.order_error, "") << where;
        int64_t wrong = 0, missing = 0, extra = 0;
        for (size_t i = 0; i < c.values.size(); ++i) {
          const double want = inside_negative ? signed_exact[i] : std::sqrt(exact2[i]);
          if (std::abs(want) > limit * (1 + 1e-6)) {
            extra += c.times_delivered[i] != 0;
            continue;
          }
          if (std::abs(want) > limit * (1 - 1e-6)) continue;  // on the limit: float rounding decides
          missing += c.times_delivered[i] != 1;
          wrong += c.times_delivered[i] == 1 && std::abs(c.values[i] - want) > 1e-5 * (1 + std::abs(want));
        }
        EXPECT_EQ(missing, 0) << where;
        EXPECT_EQ(extra, 0) << where;
        EXPECT_EQ(wrong, 0) << where;
      }
}

// The multi-label EDT (seung-lab edt's edt::edt semantics) against brute force: a voxel of label L != 0 measured to
// the nearest voxel of another label (the black border: the grid's outside is label 0), label 0 at 0 — few large
// labels, many small ones, noise (every voxel its own run), cubic and anisotropic, whole grid and within limits.
TEST(SeparableEdtTest, MultiLabelEdtMatchesBruteForce) {
  const Coord d{23, 19, 14};
  std::mt19937_64 rng(3);
  std::vector<uint32_t> noise(size_t(d.x) * d.y * d.z);
  for (uint32_t& v : noise) v = uint32_t(rng() % 5);
  const std::vector<std::pair<std::string, std::vector<uint32_t>>> volumes = {
      {"2 labels", labelBlobs(d, 2, 5, 9, 1)},
      {"30 labels", labelBlobs(d, 30, 2, 5, 2)},
      {"noise", noise},
  };
  std::vector<uint32_t> no_zero = labelBlobs(d, 9, 3, 7, 4);  // no background: every voxel some label
  for (uint32_t& v : no_zero) v += 1;
  for (const Vec3d& spacing : {Vec3d{1, 1, 1}, Vec3d{0.5, 0.5, 2.5}, Vec3d{1.2, 0.7, 0.9}}) {
    const Grid grid({0, 0, 0}, spacing, d);
    for (const auto& [name, labels] : volumes)
      for (bool black : {false, true}) {
        const std::vector<double> exact = oracle::otherLabelDistance(d.x, d.y, d.z, labels, spacingOf(grid), black);
        for (double limit : {std::numeric_limits<double>::infinity(), 1.7, 2.2, 3.1}) {
          BandOptions o;
          o.limit_world = limit;
          o.segment_length_world = limit > 3 ? 0.0 : 0.6;
          o.max_chunk_bricks = limit > 2 ? 4 : 0;  // chunked: the band in two parts along z
          const VoxelType type = name == "noise" ? VoxelType::kUint8 : VoxelType::kUint16;
          const Collected c = run(grid, asVolume(d, labels, type), {true, false, black ? kAllFaces : uint8_t(0)}, o);
          const std::string where = fmt::format("{} spacing {},{},{} black {} limit {}", name, spacing.x, spacing.y,
                                                spacing.z, black, limit);
          EXPECT_EQ(c.order_error, "") << where;
          int64_t wrong = 0, missing = 0, extra = 0;
          for (size_t i = 0; i < c.values.size(); ++i) {
            const double want = exact[i];
            if (want > limit * (1 + 1e-6)) {
              extra += c.times_delivered[i] != 0;
              continue;
            }
            if (want > limit * (1 - 1e-6)) continue;
            missing += c.times_delivered[i] != 1;
            if (c.times_delivered[i] == 1 && std::abs(c.values[i] - want) > 1e-5 * (1 + want) && wrong++ == 0)
              ADD_FAILURE() << where << ": voxel " << i << " (label " << labels[i] << ") got " << c.values[i]
                            << ", want " << want;
          }
          EXPECT_EQ(missing, 0) << where;
          EXPECT_EQ(extra, 0) << where;
          EXPECT_EQ(wrong, 0) << where;
        }
      }
    // Every voxel labelled: without a black border the distances are to other labels only.
    const std::vector<double> exact = oracle::otherLabelDistance(d.x, d.y, d.z, no_zero, spacingOf(grid), false);
    const Collected c = run(grid, asVolume(d, no_zero, VoxelType::kUint32), {true, false, 0}, {});
    int64_t wrong = 0;
    for (size_t i = 0; i < c.values.size(); ++i) wrong += std::abs(c.values[i] - exact[i]) > 1e-5 * (1 + exact[i]);
    EXPECT_EQ(wrong, 0) << "no background, spacing " << spacing.x << "," << spacing.y << "," << spacing.z;
  }
}

// Nearest labels: each voxel's nearest seed's label (scipy's return_indices looked up in the volume), wherever the
// nearest seed is unique; the distances unchanged; signed fields too; whole grid and within a limit.
TEST(SeparableEdtTest, NearestLabelsMatchBruteForceWhereTheNearestSeedIsUnique) {
  const Coord d{26, 21, 17};
  std::vector<uint32_t> labels(size_t(d.x) * d.y * d.z, 0);
  std::mt19937_64 rng(8);
  for (int i = 0; i < 60; ++i) labels[rng() % labels.size()] = uint32_t(1 + rng() % 40000);
  const std::vector<uint32_t> blobs = labelBlobs(d, 6, 1.5, 4, 9);
  for (size_t i = 0; i < labels.size(); ++i)
    if (blobs[i]) labels[i] = 50000 + blobs[i];
  for (const Vec3d& spacing : {Vec3d{1, 1, 1}, Vec3d{0.7, 0.7, 2.5}}) {
    const Grid grid({0, 0, 0}, spacing, d);
    std::vector<uint32_t> nearest;
    std::vector<bool> unique;
    oracle::nearestSeedLabel(d.x, d.y, d.z, labels, spacingOf(grid), &nearest, &unique);
    for (double limit : {std::numeric_limits<double>::infinity(), 2.2})
      for (bool inside_negative : {false, true}) {
        BandOptions o;
        o.limit_world = limit;
        o.closest_features = true;
        o.segment_length_world = 0.9;
        const Collected c = run(grid, asVolume(d, labels, VoxelType::kUint32), {false, inside_negative, false}, o);
        const std::string where = fmt::format("spacing {},{},{} limit {} signed {}", spacing.x, spacing.y, spacing.z,
                                              limit, inside_negative);
        EXPECT_EQ(c.order_error, "") << where;
        int64_t wrong = 0, checked = 0;
        for (size_t i = 0; i < c.values.size(); ++i) {
          if (c.times_delivered[i] != 1) continue;
          if (labels[i] != 0) {
            wrong += c.closest[i] != int64_t(labels[i]);  // a seed is its own nearest
            continue;
          }
          if (!unique[i]) continue;
          ++checked;
          if (c.closest[i] != int64_t(nearest[i]) && wrong++ == 0)
            ADD_FAILURE() << where << ": voxel " << i << " got label " << c.closest[i] << ", want " << nearest[i];
        }
        EXPECT_EQ(wrong, 0) << where;
        EXPECT_GT(checked, 1000) << where;
      }
  }
}

TEST(SeparableEdtTest, LabelsIdenticalForAnyThreadCountAndStoppable) {
  const Coord d{70, 66, 52};
  const Grid grid({0, 0, 0}, Vec3d{0.5, 0.5, 1.5}, d);
  const LabelVolume labels = asVolume(d, labelBlobs(d, 40, 3, 9, 12), VoxelType::kUint16);
  for (double limit : {std::numeric_limits<double>::infinity(), 2.5})
    for (bool multi : {true, false}) {
      BandOptions o;
      o.limit_world = limit;
      o.segment_length_world = 1;
      o.closest_features = !multi;
      const VolumeMeasure m{multi, false, multi ? kAllFaces : uint8_t(0)};
      o.threads = 1;
      const Collected one = run(grid, labels, m, o);
      o.threads = 2;
      const Collected two = run(grid, labels, m, o);
      EXPECT_GT(one.result.voxels, 10000);
      EXPECT_EQ(std::memcmp(one.values.data(), two.values.data(), one.values.size() * sizeof(float)), 0);
      EXPECT_EQ(one.closest, two.closest);
      Interrupter stop;
      stop.cancel(Status::Code::kCancelled, "test");
      o.interrupter = &stop;
      const Collected stopped = run(grid, labels, m, o);
      EXPECT_TRUE(stopped.result.interrupted);
      EXPECT_EQ(stopped.result.voxels, 0);
    }
}

// With a limit and chunks, a tall volume's band comes in two parts along z: exact against brute force for the seed
// field (signed, anisotropic, nearest labels) and the multi-label EDT with a black border, each voxel once, in order,
// one entry per segment in the stats.
TEST(SeparableEdtTest, WithALimitATallVolumeComesInTwoPartsExactly) {
  const Coord d{21, 18, 90};
  const std::vector<uint32_t> labels = labelBlobs(d, 14, 1.5, 5, 12);
  std::vector<uint8_t> mask(labels.size());
  for (size_t i = 0; i < labels.size(); ++i) mask[i] = labels[i] != 0;
  for (const Vec3d& spacing : {Vec3d{1, 1, 1}, Vec3d{0.7, 0.7, 1.9}}) {
    const Grid grid({0, 0, 0}, spacing, d);
    const double sp[3] = {spacing.x, spacing.y, spacing.z};
    const std::vector<double> signed_exact = oracle::signedEdt(d.x, d.y, d.z, mask, sp);
    const std::vector<double> other_label = oracle::otherLabelDistance(d.x, d.y, d.z, labels, spacingOf(grid), true);
    std::vector<uint32_t> nearest;
    std::vector<bool> unique;
    oracle::nearestSeedLabel(d.x, d.y, d.z, labels, spacingOf(grid), &nearest, &unique);
    for (bool multi : {false, true})
      for (double limit : {2.6, 9.5}) {
        BandOptions o;
        o.limit_world = limit;
        o.segment_length_world = 1.3;
        o.max_chunk_bricks = 3;
        o.closest_features = !multi;
        const VolumeMeasure measure{multi, !multi, multi ? kAllFaces : uint8_t(0)};
        const Collected c = run(grid, asVolume(d, labels, VoxelType::kUint16), measure, o);
        const std::string where = fmt::format("spacing {} multi {} limit {}", spacing.z, multi, limit);
        EXPECT_EQ(c.order_error, "") << where;
        int64_t wrong = 0, missing = 0, extra = 0, wrong_label = 0;
        for (size_t i = 0; i < c.values.size(); ++i) {
          const double want = multi ? other_label[i] : signed_exact[i];
          if (std::abs(want) > limit * (1 + 1e-6)) {
            extra += c.times_delivered[i] != 0;
            continue;
          }
          if (std::abs(want) > limit * (1 - 1e-6)) continue;
          missing += c.times_delivered[i] != 1;
          wrong += c.times_delivered[i] == 1 && std::abs(c.values[i] - want) > 1e-5 * (1 + std::abs(want));
          if (!multi && c.times_delivered[i] == 1 && labels[i] == 0 && unique[i])
            wrong_label += c.closest[i] != int64_t(nearest[i]);
        }
        EXPECT_EQ(missing, 0) << where;
        EXPECT_EQ(extra, 0) << where;
        EXPECT_EQ(wrong, 0) << where;
        EXPECT_EQ(wrong_label, 0) << where;
        for (size_t s = 0; s < c.result.segments.size(); ++s) EXPECT_EQ(c.result.segments[s].index, int(s)) << where;
      }
  }
}

}  // namespace
}  // namespace distband
