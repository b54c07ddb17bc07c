// MeshSign: which side of a triangle mesh a point lies on, by one of the sign methods — the one sign test of every
// caller: the grid path (core/seeds/mesh_seeds.h signs each delivered brick with it) and point queries
// (core/points/point_query.h sign each query point with it).
// Contract:
//   * The methods (SignMethod) and their names are defined here; kAuto is resolved on the mesh's edges and parts by
//     resolveSignMethod before anything is built.
//   * build() takes the mesh's vertices in the caller's frame (index space for a grid, world space for point queries)
//     and its triangles, and builds what the method needs, polling `interrupter` (then it returns its status):
//       - kPseudonormal: angle-weighted pseudonormals of faces, edges and vertices (Bærentzen & Aanæs 2005), exact for
//         closed, consistently oriented meshes; the test needs the point's closest triangle and distance.
//       - kWinding: the generalized winding number (core/mesh/winding_number.h), inside where it exceeds 0.5; robust
//         on open meshes.
//       - kParity: Embree rays in 3 fixed directions, inside where the majority cross the surface an odd number of
//         times.
//   * inside(p, triangle, distance) is the test for one point: `triangle` is p's closest triangle and `distance` its
//     distance to it, both in the frame (only kPseudonormal reads them: needsClosestTriangle()).
//   * signBrick() is the grid's batched form of the same test: it negates the values of a brick's delivered voxels
//     that lie inside, saving most tests (a voxel far from the surface signs its whole brick; for winding, one exact
//     query signs a brick, or else each 4^3 octant, then each 2^3 cell, where its value and the pseudonormal's side
//     provably fix every voxel's — docs/algorithm.md §10; for winding and parity a voxel at distance d decides the
//     voxels within d - 1 of it).
// Immutable once built; every query is thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/brick.h"
#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/seeds.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

/// kAuto (the default for meshes, decided here once): kPseudonormal for a closed mesh whose parts do not overlap,
/// kWinding otherwise; resolve it with resolveSignMethod before a sign is built.
enum class SignMethod { kAuto, kPseudonormal, kWinding, kParity, kUnsigned };
inline constexpr SignMethod kDefaultMeshSign = SignMethod::kAuto;
/// Every method, the default first.
inline constexpr SignMethod kSignMethods[] = {SignMethod::kAuto, SignMethod::kPseudonormal, SignMethod::kWinding,
                                              SignMethod::kParity, SignMethod::kUnsigned};

std::string_view signMethodName(SignMethod method);
/// "auto", "pseudonormal", "winding", "parity", "unsigned"
bool parseSignMethod(std::string_view name, SignMethod* method);

/// The method `requested` stands for on a mesh with this report: kAuto becomes kPseudonormal when the mesh is
/// closed and its parts' bounding boxes are disjoint (the pseudonormal test is exact there and the cheapest), else
/// kWinding (the pseudonormal test gives wrong-sign patches near an open mesh's holes, and wherever a point's closest
/// triangle belongs to another part than the one it lies in: parts that cross or nest); other methods are returned
/// as they are. `reason` (may be null) gets why, for users: e.g. "auto: the mesh is not closed (312 boundary edges)",
/// "auto: the mesh is closed but its parts overlap (2 parts, bounding boxes intersect)", or "requested".
SignMethod resolveSignMethod(SignMethod requested, const MeshReport& report, std::string* reason);

/// For users: e.g. "1204332 voxels signed: winding number by one query a brick 71.3 %, winding number per voxel
/// 28.7 %"; "" when nothing was signed.
std::string describeSignShares(const SignShares& shares);

class MeshSign {
 public:
  /// `method` must be kPseudonormal, kWinding or kParity. kInvalidArgument for another method or a corner out of
  /// range, kInternal when Embree cannot be started (parity), the interrupter's status when it stopped the build.
  /// The pseudonormal and winding signs keep `vertices` and `triangles` (shared: the mesh seeds' triangle sites are
  /// the same tables).
  static Status build(std::shared_ptr<const std::vector<Vec3d>> vertices,
                      std::shared_ptr<const std::vector<std::array<uint32_t, 3>>> triangles, SignMethod method,
                      const Interrupter* interrupter, std::unique_ptr<MeshSign>* out);
  ~MeshSign();
  MeshSign(const MeshSign&) = delete;
  MeshSign& operator=(const MeshSign&) = delete;

  SignMethod method() const { return method_; }
  bool needsClosestTriangle() const { return method_ == SignMethod::kPseudonormal; }
  /// Whether p lies inside; `triangle` and `distance` (p's closest triangle and its distance, in the frame) are read
  /// by the pseudonormal test only.
  bool inside(const Vec3d& p, uint32_t triangle, double distance) const;

  /// Negates the delivered values of `brick` that lie inside. The frame is the grid's unit space: voxel (x, y, z) at
  /// the point scale * (x, y, z) (core/grid.h: Grid::axisScale, all 1 on a cubic grid); values in world units,
  /// `voxel_size` per unit. `sites[i]` is the site of voxel offset i (kNoSite: none); `site_triangle` maps a site to
  /// its triangle (null: the site is the triangle).
  /// Returns how many of the brick's delivered voxels each test decided.
  SignShares signBrick(Brick& brick, const uint32_t* sites, const uint32_t* site_triangle, double voxel_size,
                       const Vec3d& scale = {1, 1, 1}) const;

  /// Bytes held (for memory budgets).
  uint64_t memoryBytes() const;
  /// An upper bound on memoryBytes() and on the build's peak for a mesh of this size.
  static uint64_t estimateBytes(SignMethod method, uint64_t vertices, uint64_t triangles);
  /// The most pieces (of at most 16 voxels) the winding sign cuts a mesh's boundary curves into: past this (long thin
  /// triangles at the boundary, a soup of them) it takes every point to lie on a boundary curve and signs every voxel
  /// by its own query.
  static constexpr uint64_t maxBoundaryPieces(uint64_t triangles) { return triangles / 4 + 4096; }
  /// The most bytes those pieces hold.
  static constexpr uint64_t maxBoundaryPieceBytes(uint64_t triangles) {
    return maxBoundaryPieces(triangles) * kBytesPerBoundaryPiece;
  }
  /// A boundary piece with its share of the structures over them (core/seeds/internal/boundary_curves.h).
  static constexpr uint64_t kBytesPerBoundaryPiece = 64 + 112;

 private:
  struct Tables;
  explicit MeshSign(SignMethod method);
  SignMethod method_;
  std::unique_ptr<Tables> tables_;
};

}  // namespace distband
