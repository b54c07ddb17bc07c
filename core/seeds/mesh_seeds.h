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
// Sign (negative inside): Seeds::sign is set unless the method is kUnsigned. It reads only immutable shared
// state (captured by shared_ptr, including the Embree scene for parity), so it is thread-safe.
//   * kPseudonormal: angle-weighted pseudonormal of the closest feature (face, edge or vertex) of the voxel's
//     site triangle (Bærentzen & Aanæs 2005). Exact for closed, consistently oriented meshes.
//   * kWinding: generalized winding number > 0.5 (robust for open meshes), hierarchical evaluation.
//   * kParity: Embree rays in 3 fixed directions, inside when the majority cross the surface an odd number of times.
//   For winding and parity a voxel at unsigned distance d decides the sign of the voxels within d - 1 of it in
//   the same brick (no surface lies between them), which saves most evaluations away from the surface.
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
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

enum class MeshSiteMode { kExactFeature, kPaper };
/// kAuto (the default for meshes, decided here once): kPseudonormal for a closed mesh, kWinding for an open one;
/// resolve it with resolveSignMethod before makeMeshSeeds.
enum class SignMethod { kAuto, kPseudonormal, kWinding, kParity, kUnsigned };
inline constexpr SignMethod kDefaultMeshSign = SignMethod::kAuto;
/// Every method, the default first.
inline constexpr SignMethod kSignMethods[] = {SignMethod::kAuto, SignMethod::kPseudonormal, SignMethod::kWinding,
                                              SignMethod::kParity, SignMethod::kUnsigned};

std::string_view meshSiteModeName(MeshSiteMode mode);
bool parseMeshSiteMode(std::string_view name, MeshSiteMode* mode);  ///< "exact-feature", "paper"
std::string_view signMethodName(SignMethod method);
/// "auto", "pseudonormal", "winding", "parity", "unsigned"
bool parseSignMethod(std::string_view name, SignMethod* method);

/// The method `requested` stands for on a mesh with this report: kAuto becomes kPseudonormal when the mesh is
/// closed (the pseudonormal test is exact there and the cheapest), else kWinding (the pseudonormal test gives
/// wrong-sign patches near an open mesh's holes); other methods are returned as they are. `reason` (may be null)
/// gets why, for users: e.g. "auto: the mesh is open (312 boundary edges)", or "requested".
SignMethod resolveSignMethod(SignMethod requested, const MeshReport& report, std::string* reason);

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

Status makeMeshSeeds(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options, Seeds* out,
                     MeshSeedStats* stats = nullptr);

}  // namespace distband
