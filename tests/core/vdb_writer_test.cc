// Tests for core/io/vdb_writer (VdbFieldBuilder) and core/io/vdb_reader: a signed sphere field streamed in as
// segments, written, read back through OpenVDB, and checked voxel by voxel.
#include <cmath>
#include <filesystem>
#include <limits>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include "core/dense_field.h"
#include "core/engine.h"
#include "core/io/vdb_reader.h"
#include "core/io/vdb_writer.h"
#include "core/seeds/mesh_seeds.h"
#include "tests/support/brute_mesh.h"

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
  ASSERT_EQ(makeMeshSeeds(grid, sphere, so, &seeds), "");
  EngineOptions eo;
  eo.limit_world = limit;
  eo.segment_length_world = h;  // several segments, streamed in one by one
  VdbFieldBuilder builder(grid, float(limit));
  DenseField dense(grid, std::numeric_limits<float>::quiet_NaN());
  int segments = 0;
  computeDistanceField(grid, seeds, eo, [&](SegmentBricks&& s) {
    builder.add(s);
    dense.add(s);
    ++segments;
  });
  EXPECT_GE(segments, 3);
  EXPECT_EQ(builder.activeVoxels(), dense.written());

  const fs::path path = fs::temp_directory_path() / ("distband_vdb_writer_" + std::to_string(::getpid()) + ".vdb");
  ASSERT_EQ(builder.write(path.string()), "");
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

TEST(VdbWriterTest, ReportsUnwritablePathsAndUnreadableFiles) {
  const Grid grid({0, 0, 0}, 1.0, {8, 8, 8});
  VdbFieldBuilder builder(grid, 3.0f);
  Brick b;
  b.mask.set(0);
  b.values[0] = 1.5f;
  builder.add(b);
  const std::string bad = "/nonexistent-dir/field.vdb";
  const std::string error = builder.write(bad);
  EXPECT_NE(error.find(bad), std::string::npos) << error;
  openvdb::FloatGrid::Ptr out;
  EXPECT_NE(readVdb("/nonexistent-dir/none.vdb", &out), "");
  EXPECT_FALSE(out);
}

}  // namespace
}  // namespace distband
