// Mesh seeds: the initial band and site table for the distance to a triangle mesh, and its sign.
// Contract: makeMeshSeeds() scans, for every triangle, the voxels within `band_radius_voxels` of it (an exact
// point–triangle scan, brick by brick, in parallel on the caller's TBB arena); each band voxel gets its exact
// closest triangle (ties: the lowest triangle index, so the band is deterministic). The band thus holds every
// voxel whose cell the surface crosses (distance <= sqrt(3)/2) and, with the default radius 1.5, their face
// neighbours and most edge neighbours. Band voxels farther than `limit_voxels` are dropped. Distances are measured in
// unit space (core/grid.h); on an anisotropic grid the radius is multiplied by the largest axis scale, so the band
// holds voxels on both sides of the surface along every axis.
//   * kExactFeature (default): sites are the mesh's triangles in unit space (Seeds::kTriangle); the engine
//     propagates triangle ids and evaluates the exact point–triangle distance where they arrive.
//   * kPaper: sites are the band voxels' closest points (Seeds::kPoint), propagated as CP + PQ (paper eq. 2);
//     each site remembers its triangle for the sign.
// A big mesh seen through a small grid (a tile's window): with a finite limit and pseudonormal or no signs, only the
// triangles whose bounding box grown by the limit reaches the grid are read (one pass over the triangles' corners;
// the copies, normals, sign tables and sites then hold those alone, in the mesh's order). Values, closest triangles and
// signs are the whole mesh's (closest features keep the mesh's triangle ids: Seeds::site_feature).
// Sign (negative inside): Seeds::sign is set unless the method is kUnsigned: MeshSign::signBrick
// (core/seeds/mesh_sign.h, the sign test point queries use too) on the mesh in index space, the voxel's site triangle
// its closest. It reads only immutable shared state (captured by shared_ptr), so it is thread-safe.
// Errors come back as a Status, `out` then untouched: kInvalidArgument (empty mesh, invalid grid or options),
// kResourceExhausted (more triangles than the engine has site ids), the interrupter's status when it stopped.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <string_view>

#include "core/grid.h"
#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_sign.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

enum class MeshSiteMode { kExactFeature, kPaper };

std::string_view meshSiteModeName(MeshSiteMode mode);
bool parseMeshSiteMode(std::string_view name, MeshSiteMode* mode);  ///< "exact-feature", "paper"

struct MeshSeedOptions {
  MeshSiteMode mode = MeshSiteMode::kExactFeature;
  SignMethod sign = SignMethod::kPseudonormal;  ///< never kAuto (resolveSignMethod)
  double band_radius_voxels = 1.5;  ///< initial band: voxels within this distance of a triangle, in (0, 8]
  double limit_voxels = std::numeric_limits<double>::infinity();  ///< band voxels beyond are dropped
  /// Polled throughout (the scan, sorts, sign tables, the winding-number tree, Embree's BVH build); when it trips,
  /// makeMeshSeeds returns the interrupter's status.
  const Interrupter* interrupter = nullptr;
};

struct MeshSeedStats {
  int64_t band_voxels = 0;
  int64_t bricks_scanned = 0;
  double seconds = 0;
};

/// The (brick, triangle) pairs makeMeshSeeds' scan lists for `mesh` on `grid`: for each triangle, the bricks its
/// bounding box grown by the band radius overlaps, clipped to the grid. The scan holds kMeshScanPairBytes a pair while
/// it runs, and long thin triangles make many (a needle across a 4096^3 grid, 512): a memory estimate counts them
/// (core/field/field_memory.h). O(triangles), no allocation.
uint64_t meshScanPairs(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options);
inline constexpr uint64_t kMeshScanPairBytes = 16;

Status makeMeshSeeds(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options, Seeds* out,
                     MeshSeedStats* stats = nullptr);

}  // namespace distband
