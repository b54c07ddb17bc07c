// Tests for core/io/vdb_writer (VdbFieldBuilder), core/io/vdb_tree and core/io/vdb_file: fields written without
// OpenVDB and read back with OpenVDB's own reader (tests/support/vdb_reader) — a signed sphere field streamed in as
// segments, checked voxel by voxel; random bricks compared node by node with the tree OpenVDB builds and
// flood-fills itself from the same bricks; closest-id grids, metadata, empty fields, unwritable paths.
#include <cmath>
#include <filesystem>
#include <limits>

#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>

#include "core/io/dense_field.h"
#include "core/band/band_engine.h"
#include "tests/support/vdb_reader.h"
#include "core/io/vdb_writer.h"
#include "core/seeds/mesh_seeds.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

TEST(VdbWriterTest, SegmentsRoundTripAsALevelSet) {
  const TriangleMesh sphere = testing::makeSphereMesh({0, 0, 0}, 1.0, 16, 32);
  const double h = 0.1;
  const Grid grid({-1.6, -1.5, -1.4}, h, {33, 31, 29});
  const double limit = 3 * h;
  MeshSeedOptions so;
  so.limit_voxels = 3;
  Seeds seeds;
  ASSERT_TRUE(IsOk(makeMeshSeeds(grid, sphere, so, &seeds)));
  BandOptions eo;
  eo.limit_world = limit;
  eo.segment_length_world = h;  // several segments, streamed in one by one
  VdbFieldBuilder builder(grid, float(limit));
  DenseField dense(grid, std::numeric_limits<float>::quiet_NaN());
  int segments = 0;
  computeBandField(grid, seeds, eo, [&](SegmentBricks&& s) {
    builder.add(s);
    dense.add(s);
    ++segments;
  });
  EXPECT_GE(segments, 3);
  EXPECT_EQ(builder.activeVoxels(), dense.written());

  const fs::path path = fs::temp_directory_path() / ("distband_vdb_writer_" + std::to_string(::getpid()) + ".vdb");
  ASSERT_TRUE(IsOk(builder.write(path.string())));
  EXPECT_FALSE(fs::exists(path.string() + ".tmp"));
  openvdb::FloatGrid::Ptr vdb;
  ASSERT_EQ(readVdb(path.string(), &vdb), "");
  fs::remove(path);

  EXPECT_EQ(vdb->getName(), "distance");
  EXPECT_EQ(vdb->getGridClass(), openvdb::GRID_LEVEL_SET);
  EXPECT_FLOAT_EQ(vdb->background(), float(limit));
  EXPECT_NEAR(vdb->voxelSize()[0], h, 1e-12);
  const openvdb::Vec3d w = vdb->indexToWorld(openvdb::Coord(2, 3, 4));
  EXPECT_NEAR(w.x(), -1.6 + 0.2, 1e-12);
  EXPECT_NEAR(w.y(), -1.5 + 0.3, 1e-12);
  EXPECT_NEAR(w.z(), -1.4 + 0.4, 1e-12);
  EXPECT_EQ(int64_t(vdb->activeVoxelCount()), dense.written());

  auto acc = vdb->getConstAccessor();
  const Coord d = grid.dims();
  int64_t inside_background = 0;
  for (int z = 0; z < d.z; ++z)
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        const openvdb::Coord c(x, y, z);
        const float want = dense.at({x, y, z});
        if (!std::isnan(want)) {
          ASSERT_TRUE(acc.isValueOn(c));
          EXPECT_EQ(acc.getValue(c), want);
        } else {
          // Not delivered: +background outside, -background inside (signed flood fill).
          ASSERT_FALSE(acc.isValueOn(c));
          const double r = grid.worldOf({x, y, z}).length();
          EXPECT_EQ(acc.getValue(c), r < 1.0 ? -float(limit) : float(limit)) << x << "," << y << "," << z;
          inside_background += r < 1.0;
        }
      }
  EXPECT_GT(inside_background, 1000);
}

fs::path tempVdb(const std::string& name) {
  return fs::temp_directory_path() / ("distband_vdb_" + name + "_" + std::to_string(::getpid()) + ".vdb");
}

// Every tile (level, origin, value, active) of a tree, for comparing two trees' internal nodes and root.
std::set<std::tuple<int, int, int, int, float, bool>> tilesOf(const openvdb::FloatGrid& g) {
  std::set<std::tuple<int, int, int, int, float, bool>> tiles;
  for (auto it = g.tree().cbeginValueAll(); it; ++it)
    if (it.isTileValue())
      tiles.insert({int(it.getDepth()), it.getCoord().x(), it.getCoord().y(), it.getCoord().z(), *it, it.isValueOn()});
  return tiles;
}

// The same bricks through OpenVDB itself: leaves filled as the old OpenVDB-based writer did, then signedFloodFill.
openvdb::FloatGrid::Ptr openVdbReference(const std::vector<Brick>& bricks, float background) {
  auto g = openvdb::FloatGrid::create(background);
  auto acc = g->getAccessor();
  for (const Brick& b : bricks) {
    auto* leaf = acc.touchLeaf(openvdb::Coord(b.origin.x, b.origin.y, b.origin.z));
    for (int i = 0; i < kBrickVoxels; ++i)
      if (b.mask.test(i)) leaf->setValueOn(openvdb::Index(i), b.values[size_t(i)]);
  }
  openvdb::tools::signedFloodFill(g->tree());
  return g;
}

// Random signed bricks: scattered near the origin, in several 4096^3 root children (one z-run of inside children with
// an empty child-sized gap between them, which OpenVDB fills with inside root tiles), and bricks all inside.
std::vector<Brick> randomBricks(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> value(-2.f, 2.f);
  std::vector<Brick> bricks;
  auto add = [&](Coord origin, float bias, double fill) {
    Brick b;
    b.origin = origin;
    for (int i = 0; i < kBrickVoxels; ++i)
      if (std::uniform_real_distribution<double>(0, 1)(rng) < fill) {
        b.mask.set(i);
        b.values[size_t(i)] = std::clamp(value(rng) + bias, -2.9f, 2.9f);
      }
    if (!b.mask.empty()) bricks.push_back(b);
  };
  std::set<std::tuple<int, int, int>> cells;  // distinct origins: the builder and the reference add in other orders
  std::uniform_int_distribution<int> cell(0, 40);
  while (cells.size() < 300) cells.insert({8 * cell(rng), 8 * cell(rng), 8 * cell(rng)});
  for (const auto& [x, y, z] : cells) add({x, y, z}, 0.f, 0.3);
  add({4088, 4088, 4088}, -5.f, 1.0);       // the last brick of root child (0, 0, 0): inside
  add({4088, 4088, 3 * 4096}, -5.f, 0.5);   // root child (0, 0, 12288) starts inside: tiles at z = 4096, 8192
  add({8200, 16, 24}, 5.f, 0.2);            // another root child, outside
  add({1000, 2000, 3000}, -5.f, 0.01);      // a nearly empty inside brick
  return bricks;
}

// An anisotropic grid: OpenVDB reads back each axis's voxel size and the world position of every voxel.
TEST(VdbWriterTest, AnisotropicSpacingIsTheTransformsScale) {
  const Grid grid({-1.5, 2.0, 0.25}, Vec3d{0.7, 0.7, 2.5}, {20, 18, 9});
  VdbFieldBuilder builder(grid, 2.0f);
  Brick b;
  b.origin = {8, 8, 0};
  for (int i = 0; i < kBrickVoxels; i += 3) {
    b.values[i] = 0.5f;
    b.mask.set(i);
  }
  builder.add(b);
  const fs::path path = fs::temp_directory_path() / ("distband_vdb_aniso_" + std::to_string(::getpid()) + ".vdb");
  ASSERT_TRUE(IsOk(builder.write(path.string())));
  openvdb::FloatGrid::Ptr vdb;
  ASSERT_EQ(readVdb(path.string(), &vdb), "");
  fs::remove(path);
  EXPECT_NEAR(vdb->voxelSize()[0], 0.7, 1e-12);
  EXPECT_NEAR(vdb->voxelSize()[1], 0.7, 1e-12);
  EXPECT_NEAR(vdb->voxelSize()[2], 2.5, 1e-12);
  EXPECT_FALSE(vdb->hasUniformVoxels());
  const openvdb::Vec3d w = vdb->indexToWorld(openvdb::Coord(2, 3, 4));
  EXPECT_NEAR(w.x(), -1.5 + 2 * 0.7, 1e-12);
  EXPECT_NEAR(w.y(), 2.0 + 3 * 0.7, 1e-12);
  EXPECT_NEAR(w.z(), 0.25 + 4 * 2.5, 1e-12);
  EXPECT_EQ(vdb->activeVoxelCount(), openvdb::Index64(b.mask.count()));
}

TEST(VdbWriterTest, MatchesOpenVdbsOwnFloodFilledTreeBitForBit) {
  const float background = 3.f;
  const Grid grid({0.5, -1, 2}, 0.25, {12300, 12300, 12300});
  for (unsigned seed : {1u, 2u, 3u}) {
    SCOPED_TRACE(seed);
    const std::vector<Brick> bricks = randomBricks(seed);
    VdbFieldBuilder builder(grid, background);
    // Half as single bricks, half as one segment (the parallel fill).
    SegmentBricks segment;
    for (size_t i = 0; i < bricks.size(); ++i) {
      if (i % 2) builder.add(bricks[i]);
      else segment.bricks.push_back(bricks[i]);
    }
    // In (z, y, x) order, as the engine delivers them (the parallel path); unordered segments are applied in order.
    std::sort(segment.bricks.begin(), segment.bricks.end(), [](const Brick& a, const Brick& b) {
      return std::tie(a.origin.z, a.origin.y, a.origin.x) < std::tie(b.origin.z, b.origin.y, b.origin.x);
    });
    builder.add(segment);
    const fs::path path = tempVdb("random");
    ASSERT_TRUE(IsOk(builder.write(path.string())));
    openvdb::FloatGrid::Ptr ours;
    ASSERT_EQ(readVdb(path.string(), &ours), "");
    fs::remove(path);
    const openvdb::FloatGrid::Ptr ref = openVdbReference(bricks, background);

    EXPECT_EQ(ours->background(), ref->background());
    EXPECT_EQ(ours->tree().nodeCount(), ref->tree().nodeCount());
    EXPECT_EQ(ours->activeVoxelCount(), ref->activeVoxelCount());
    const auto tiles = tilesOf(*ref);
    EXPECT_EQ(tilesOf(*ours), tiles);
    // The root tiles of the z-run above are exercised (depth 0: the root's own tiles).
    EXPECT_GE(std::count_if(tiles.begin(), tiles.end(), [](const auto& t) { return std::get<0>(t) == 0; }), 2);
    size_t leaves = 0;
    for (auto it = ref->tree().cbeginLeaf(); it; ++it, ++leaves) {
      const auto* mine = ours->tree().probeConstLeaf(it->origin());
      ASSERT_TRUE(mine) << it->origin();
      EXPECT_EQ(mine->getValueMask(), it->getValueMask());
      for (openvdb::Index i = 0; i < 512; ++i) ASSERT_EQ(mine->getValue(i), it->getValue(i)) << it->origin() << " " << i;
    }
    EXPECT_EQ(leaves, ours->tree().leafCount());
    // The tree read in memory answers the same values as OpenVDB's, leaves, tiles and root tiles alike.
    auto acc = ref->getConstAccessor();
    for (const Coord& c : {Coord{0, 0, 0}, Coord{5000, 4090, 4090}, Coord{4090, 4090, 5000}, Coord{4090, 4090, 9000},
                           Coord{9000, 9000, 9000}, Coord{8203, 17, 30}, Coord{1001, 2002, 3003}, Coord{-5, 3, 3}})
      EXPECT_EQ(builder.value(c), acc.getValue(openvdb::Coord(c.x, c.y, c.z))) << c.x << "," << c.y << "," << c.z;
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> near(-8, 340);
    for (int i = 0; i < 20000; ++i) {
      const Coord c{near(rng), near(rng), near(rng)};
      ASSERT_EQ(builder.value(c), acc.getValue(openvdb::Coord(c.x, c.y, c.z))) << c.x << "," << c.y << "," << c.z;
    }
  }
}

TEST(VdbWriterTest, ClosestIdsAndMetadataRoundTrip) {
  const Grid grid({1, 2, 3}, 0.5, {64, 40, 5000});
  for (bool wide : {false, true}) {
    SCOPED_TRACE(wide);
    VdbFieldBuilder builder(grid, 2.f);
    builder.addClosestGrid(wide);
    std::vector<Brick> bricks(3);
    bricks[0].origin = {8, 16, 0};
    bricks[1].origin = {8, 16, 4800};
    bricks[2].origin = {56, 32, 8};  // no closest ids: no leaf in "closest"
    for (int b = 0; b < 3; ++b)
      for (int i = b; i < kBrickVoxels; i += 3) {
        bricks[size_t(b)].mask.set(i);
        bricks[size_t(b)].values[size_t(i)] = 0.25f * float(i % 7) - 0.75f;
      }
    for (int b = 0; b < 2; ++b) {
      bricks[size_t(b)].closest.assign(kBrickVoxels, -1);
      for (int i = 0; i < kBrickVoxels; ++i)
        if (bricks[size_t(b)].mask.test(i)) bricks[size_t(b)].closest[size_t(i)] = wide ? (int64_t(1) << 40) + i : 1000 * b + i;
    }
    for (const Brick& b : bricks) builder.add(b);
    builder.setRunState(false, 7);
    const fs::path path = tempVdb("closest");
    ASSERT_TRUE(IsOk(builder.write(path.string())));
    openvdb::FloatGrid::Ptr distance;
    ASSERT_EQ(readVdb(path.string(), &distance), "");
    EXPECT_EQ(distance->metaValue<openvdb::Vec3i>("distband_dims"), openvdb::Vec3i(64, 40, 5000));
    EXPECT_EQ(distance->metaValue<bool>("distband_complete"), false);
    EXPECT_EQ(distance->metaValue<int32_t>("distband_segments"), 7);
    EXPECT_EQ(distance->metaValue<std::string>("name"), "distance");
    EXPECT_EQ(distance->metaValue<int64_t>("file_voxel_count"), int64_t(distance->activeVoxelCount()));
    EXPECT_EQ(distance->metaValue<openvdb::Vec3i>("file_bbox_min"), openvdb::Vec3i(8, 16, 0));
    EXPECT_EQ(distance->metaValue<openvdb::Vec3i>("file_bbox_max"), openvdb::Vec3i(63, 39, 4807));
    const openvdb::Vec3d w = distance->indexToWorld(openvdb::Coord(2, 3, 4));
    EXPECT_EQ(w, openvdb::Vec3d(2, 3.5, 5));
    openvdb::GridBase::Ptr base;
    ASSERT_EQ(readVdbGrid(path.string(), "closest", &base), "");
    fs::remove(path);
    auto check = [&](const auto& ids) {
      EXPECT_EQ(ids.background(), -1);
      EXPECT_EQ(ids.tree().leafCount(), 2u);
      auto acc = ids.getConstAccessor();
      for (int b = 0; b < 3; ++b)
        for (int i = 0; i < kBrickVoxels; ++i) {
          const Coord c = bricks[size_t(b)].origin + brickLocal(i);
          const openvdb::Coord oc(c.x, c.y, c.z);
          const bool on = b < 2 && bricks[size_t(b)].mask.test(i);
          ASSERT_EQ(acc.isValueOn(oc), on);
          ASSERT_EQ(int64_t(acc.getValue(oc)), on ? bricks[size_t(b)].closest[size_t(i)] : -1);
        }
    };
    if (wide) {
      auto ids = openvdb::gridPtrCast<openvdb::Int64Grid>(base);
      ASSERT_TRUE(ids);
      check(*ids);
    } else {
      auto ids = openvdb::gridPtrCast<openvdb::Int32Grid>(base);
      ASSERT_TRUE(ids);
      check(*ids);
    }
  }
}

// A segment from an untrusted server may name a brick twice: both are applied, in order (the later value wins),
// without two threads filling one leaf.
TEST(VdbWriterTest, ABrickTwiceInOneSegmentIsAppliedInOrder) {
  const Grid grid({0, 0, 0}, 1.0, {64, 64, 64});
  VdbFieldBuilder builder(grid, 3.0f);
  SegmentBricks segment;
  for (int k = 0; k < 200; ++k) {
    Brick b;
    b.origin = {8 * (k % 4), 8 * (k / 4 % 4), 0};  // 16 origins, each many times
    b.mask.set(k % kBrickVoxels);
    b.values[size_t(k % kBrickVoxels)] = float(k) / 100.f;
    b.mask.set(0);
    b.values[0] = float(k) / 1000.f;
    segment.bricks.push_back(b);
  }
  builder.add(segment);
  builder.finish();
  for (int k = 0; k < 200; ++k) {
    const Coord origin{8 * (k % 4), 8 * (k / 4 % 4), 0};
    if (k % kBrickVoxels) {
      EXPECT_EQ(builder.value(origin + brickLocal(k % kBrickVoxels)), float(k) / 100.f);
    }
  }
  for (int o = 0; o < 16; ++o) {  // voxel 0 of origin o = k % 16: the last k naming it wins
    const int last = o < 8 ? 192 + o : 176 + o;
    EXPECT_EQ(builder.value({8 * (o % 4), 8 * (o / 4), 0}), float(last) / 1000.f);
  }
}

TEST(VdbWriterTest, AnEmptyFieldIsAReadableEmptyLevelSet) {
  const Grid grid({0, 0, 0}, 1.0, {8, 8, 8});
  VdbFieldBuilder builder(grid, 3.0f);
  const fs::path path = tempVdb("empty");
  ASSERT_TRUE(IsOk(builder.write(path.string())));
  openvdb::FloatGrid::Ptr vdb;
  ASSERT_EQ(readVdb(path.string(), &vdb), "");
  fs::remove(path);
  EXPECT_EQ(vdb->activeVoxelCount(), 0u);
  EXPECT_EQ(vdb->background(), 3.f);
  EXPECT_EQ(vdb->getGridClass(), openvdb::GRID_LEVEL_SET);
  EXPECT_EQ(builder.value({3, 3, 3}), 3.f);
}

TEST(VdbWriterTest, ReportsUnwritablePathsAndUnreadableFiles) {
  const Grid grid({0, 0, 0}, 1.0, {8, 8, 8});
  VdbFieldBuilder builder(grid, 3.0f);
  Brick b;
  b.mask.set(0);
  b.values[0] = 1.5f;
  builder.add(b);
  const std::string bad = "/nonexistent-dir/field.vdb";
  EXPECT_TRUE(IsError(builder.write(bad), Status::Code::kIoError,
                      bad + ": cannot write the VDB file: " + bad + ".tmp: cannot open for writing"));
  openvdb::FloatGrid::Ptr out;
  EXPECT_NE(readVdb("/nonexistent-dir/none.vdb", &out), "");
  EXPECT_FALSE(out);
}

}  // namespace
}  // namespace distband
