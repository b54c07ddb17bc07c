// Field memory estimates that depend on a mesh's shape, not only its size: long thin triangles make the seed scan
// list many (brick, triangle) pairs, which the estimate must count (an upload of stacked needles held 2.2 GB on a
// 1024 x 9 x 8 grid while estimated at about 104 MiB).
#include "core/field/field_memory.h"

#include <gtest/gtest.h>

#include "core/field/field_plan.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/mesh_sign.h"

namespace distband {
namespace {

// `count` copies of a needle along x across a 256-voxel grid, stacked (each its own vertices).
TriangleMesh stackedNeedles(int count) {
  TriangleMesh mesh;
  for (int i = 0; i < count; ++i) {
    const double y = 10 + 1e-3 * i;
    const auto v = uint32_t(mesh.vertices.size());
    mesh.vertices.insert(mesh.vertices.end(), {Vec3d{0.5, y, 10}, Vec3d{255, y, 10}, Vec3d{255, y + 0.5, 10.5}});
    mesh.triangles.push_back({v, v + 1, v + 2});
  }
  return mesh;
}

Grid grid256() { return Grid({0, 0, 0}, 1.0, {256, 32, 32}); }  // unit voxels at the origin

TEST(FieldMemoryTest, ScanPairsFollowTheTrianglesLengthNotTheirCount) {
  const Grid grid = grid256();
  MeshSeedOptions options;  // band radius 1.5 voxels
  const uint64_t one = meshScanPairs(grid, stackedNeedles(1), options);
  // Voxels 0..255 along x at radius 1.5: bricks 0..31; voxels 9..12 along y and z: brick 1.
  EXPECT_EQ(one, 32u);
  EXPECT_EQ(meshScanPairs(grid, stackedNeedles(100), options), 100 * one);
}

TEST(FieldMemoryTest, MeshEstimatesCountTheScanPairsAndTheBoundaryPieces) {
  const Grid grid = grid256();
  FieldPlan plan;
  plan.seeds = SeedKind::kMesh;
  plan.mesh_sign = SignMethod::kPseudonormal;
  SeedCounts counts;
  counts.mesh_triangles = 1000;
  counts.mesh_vertices = 3000;
  counts.mesh_area_voxels = 1000 * 64;
  const uint64_t touched = 256 * 32 * 32;
  const uint64_t without = estimateFieldMemory(plan, grid, counts, touched, 0).seed_bytes;
  counts.mesh_scan_pairs = 1000 * 128;
  const uint64_t with_pairs = estimateFieldMemory(plan, grid, counts, touched, 0).seed_bytes;
  EXPECT_GE(with_pairs - without, counts.mesh_scan_pairs * kMeshScanPairBytes);
  plan.mesh_sign = SignMethod::kWinding;
  const uint64_t winding = estimateFieldMemory(plan, grid, counts, touched, 0).seed_bytes;
  EXPECT_GE(winding - with_pairs, MeshSign::maxBoundaryPieceBytes(counts.mesh_triangles));
}

}  // namespace
}  // namespace distband
