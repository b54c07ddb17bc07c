// Tests for makeMeshSeeds on a window of a mesh's grid (core/seeds/mesh_seeds.h): with a limit and pseudonormal or no
// signs only the triangles within reach of the window are read. The window's band, closest triangles and distances
// must then be those the whole mesh gives the same window (winding signs read the whole mesh: the reference), its
// signs the whole grid's, and its distances within the plan's accuracy of the brute-force oracle.
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

#include <gtest/gtest.h>

#include "core/band/band_engine.h"
#include "core/io/dense_field.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

struct Case {
  const char* mesh;
  MeshSiteMode mode;
  SignMethod sign;  // pseudonormal or unsigned: the methods that read only the triangles in reach
};

TriangleMesh load(const std::string& name) {
  TriangleMesh mesh;
  EXPECT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR "/meshes/") + name, &mesh, nullptr)));
  return mesh;
}

using VoxelKey = std::tuple<int, int, int>;

// Each band voxel's closest feature, the mesh's triangle id.
std::map<VoxelKey, uint32_t> bandOf(const Seeds& seeds) {
  std::map<VoxelKey, uint32_t> band;
  for (const BandVoxel& b : seeds.band)
    band[{b.voxel.x, b.voxel.y, b.voxel.z}] = seeds.site_feature.empty() ? b.site : seeds.site_feature[b.site];
  return band;
}

DenseField fieldOf(const Grid& grid, const Seeds& seeds, double limit_voxels, MeshSiteMode mode) {
  BandOptions o;
  o.limit_world = limit_voxels * grid.voxelSize();
  if (mode == MeshSiteMode::kPaper) o.stencil = StencilKind::kCubic26;
  DenseField field(grid, std::numeric_limits<float>::quiet_NaN());
  computeBandField(grid, seeds, o, [&](SegmentBricks&& s) { field.add(s); });
  return field;
}

class MeshWindowTest : public ::testing::TestWithParam<Case> {};

TEST_P(MeshWindowTest, AWindowReadsOnlyTheTrianglesInReachAndComputesWhatTheWholeMeshGivesIt) {
  const Case c = GetParam();
  const TriangleMesh mesh = load(c.mesh);
  Grid grid;
  MeshGridOptions go;
  go.resolution = 64;
  go.padding_voxels = 4;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, go, {}, &grid)));
  const double limit = 3;
  MeshSeedOptions so;
  so.mode = c.mode;
  so.sign = c.sign;
  so.limit_voxels = limit;
  // A window of an eighth of the grid, from one face of the grid through the middle of the mesh.
  const Coord d = grid.dims();
  const VoxelBox box{{0, d.y / 4, d.z / 4}, {d.x / 2, d.y / 2, d.z / 2}};
  const Grid window = grid.window(box);
  Seeds part;
  ASSERT_TRUE(IsOk(makeMeshSeeds(window, mesh, so, &part)));
  if (c.mode == MeshSiteMode::kExactFeature) {  // fewer triangles read; closest features name the mesh's
    EXPECT_GT(part.triangles.size(), 0u);
    EXPECT_LT(part.triangles.size(), mesh.triangles.size() * 3 / 4);
    ASSERT_EQ(part.site_feature.size(), part.triangles.size());
  }

  // The reference: the same window from the whole mesh (winding signs read every triangle).
  MeshSeedOptions whole_options = so;
  whole_options.sign = SignMethod::kWinding;
  Seeds whole;
  ASSERT_TRUE(IsOk(makeMeshSeeds(window, mesh, whole_options, &whole)));
  EXPECT_EQ(whole.site_feature.size(), c.mode == MeshSiteMode::kPaper ? whole.band.size() : 0u);
  const std::map<VoxelKey, uint32_t> mine = bandOf(part), all = bandOf(whole);
  EXPECT_GT(all.size(), 100u);
  EXPECT_EQ(mine, all) << "the band or its closest triangles differ";

  // The fields: the same voxels at the same distances everywhere in the window.
  const DenseField part_field = fieldOf(window, part, limit, c.mode);
  const DenseField whole_field = fieldOf(window, whole, limit, c.mode);
  int64_t delivered = 0;
  for (int z = 0; z < box.dims.z; ++z)
    for (int y = 0; y < box.dims.y; ++y)
      for (int x = 0; x < box.dims.x; ++x) {
        const float a = part_field.at({x, y, z}), b = whole_field.at({x, y, z});
        ASSERT_EQ(std::isnan(a), std::isnan(b)) << "delivered in one only at " << x << "," << y << "," << z;
        if (std::isnan(a)) continue;
        ++delivered;
        ASSERT_EQ(std::abs(a), std::abs(b)) << "at " << x << "," << y << "," << z;
      }
  EXPECT_GT(delivered, 1000);

  // Away from the window's faces inside the grid (nearer, the window misses triangles beyond them; tiles have
  // halos): the whole grid's sign, and the brute-force distance within the plan's accuracy.
  Seeds grid_seeds;
  ASSERT_TRUE(IsOk(makeMeshSeeds(grid, mesh, so, &grid_seeds)));
  const DenseField grid_field = fieldOf(grid, grid_seeds, limit, c.mode);
  const int margin = int(std::ceil(limit)) + 1;
  int64_t compared = 0;
  double worst = 0;
  for (int z = margin; z < box.dims.z - margin; ++z)
    for (int y = margin; y < box.dims.y - margin; ++y)
      for (int x = 0; x < box.dims.x - margin; ++x) {  // x = 0 is the grid's face
        const float a = part_field.at({x, y, z}), b = grid_field.at(box.min + Coord{x, y, z});
        if (std::isnan(a) || std::isnan(b)) continue;
        ++compared;
        if (c.sign != SignMethod::kUnsigned && std::abs(b) > 0.5 * grid.voxelSize()) {
          ASSERT_EQ(std::signbit(a), std::signbit(b)) << "sign at " << x << "," << y << "," << z;
        }
        const double exact = testing::bruteDistance(mesh, grid.worldOf(box.min + Coord{x, y, z}));
        worst = std::max(worst, std::abs(std::abs(double(a)) - exact) / grid.voxelSize());
      }
  EXPECT_GT(compared, 500);
  EXPECT_LT(worst, 0.15);
}

INSTANTIATE_TEST_SUITE_P(Meshes, MeshWindowTest,
                         ::testing::Values(Case{"bunny.obj", MeshSiteMode::kExactFeature, SignMethod::kPseudonormal},
                                           Case{"fandisk.off", MeshSiteMode::kExactFeature, SignMethod::kPseudonormal},
                                           Case{"fandisk.off", MeshSiteMode::kPaper, SignMethod::kPseudonormal},
                                           Case{"teapot.obj", MeshSiteMode::kExactFeature, SignMethod::kUnsigned}));

}  // namespace
}  // namespace distband
