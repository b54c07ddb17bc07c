// Point queries: the distance field at arbitrary points — the signed distance to the seeds, and optionally the closest
// point, the closest feature's id and the gradient — without a grid.
// Contract:
//   * PointSearch names the structures a query searches, each built once per seed set and shared (a server keeps them
//     with the cached asset): a mesh's TriangleBvh with its MeshSign (null: unsigned), a PointSet of seed points, a
//     VolumeSearch of a seed volume.
//   * Meshes: the exact distance to the closest triangle (lowest index among those at the same computed distance),
//     signed by the sign method in force — the same MeshSign test the grid path signs its voxels with, so a voxel
//     centre gets the grid's sign. Points farther than the limit have no closest triangle: they are signed by
//     `far_sign` (the winding number; a closed mesh's pseudonormal sign and its winding number agree away from the
//     surface), or by `sign` itself when it needs no closest triangle (winding, parity).
//   * Point seeds: the exact distance to the nearest seed point (lowest index among those at the same computed
//     distance), unsigned. Ties are of the computed doubles: triangles sharing the closest vertex or edge, or points
//     equally far in real arithmetic, may differ in the last bit, and the nearer by rounding is reported (the same
//     one for every thread count, chunking and order of the query points).
//   * Volumes: VolumeSearch's distance to the nearest seed voxel centre, signed when the volume is (mask-inside).
//   * Per point, within the limit: distance (world units, negative inside); closest point; feature id (the triangle,
//     seed point or seed voxel's linear index); gradient = the unit vector from the closest point to the point, times
//     the sign (the direction in which the signed distance grows fastest). Where the closest feature is not unique
//     (medial points) it is the reported feature's direction. At distance 0 the gradient is the closest triangle's
//     unit normal for meshes and 0 for point and volume seeds.
//   * Beyond the limit (|distance| > limit): distance = +limit or -limit, closest point NaN, feature -1, gradient 0;
//     such a point costs a box test or a few, and its sign.
//   * queryPoints() evaluates `count` points in parallel on the caller's TBB arena, polling options.interrupter every
//     few hundred points (it then returns the interrupter's status and the outputs are partial). It returns
//     kInvalidArgument for a non-finite query point (naming its index) or a search that lacks what the seeds need,
//     before any work. Outputs are arrays of `count` entries the caller owns; a null one is not computed.
// Thread-safe: any number of queries may search the same PointSearch at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>

#include "core/field/field_plan.h"
#include "core/interrupter.h"
#include "core/points/point_set.h"
#include "core/points/triangle_bvh.h"
#include "core/points/volume_search.h"
#include "core/seeds/mesh_sign.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

struct PointSearch {
  SeedKind seeds = SeedKind::kMesh;
  std::shared_ptr<const TriangleBvh> mesh;
  std::shared_ptr<const MeshSign> sign;      ///< meshes: null = unsigned
  std::shared_ptr<const MeshSign> far_sign;  ///< meshes signed by pseudonormals with a finite limit: kWinding
  std::shared_ptr<const PointSet> points;
  std::shared_ptr<const VolumeSearch> volume;

  bool signedField() const {
    return seeds == SeedKind::kMesh ? sign != nullptr : seeds == SeedKind::kVolume && volume && volume->insideNegative();
  }
};

struct PointQueryOptions {
  double limit = std::numeric_limits<double>::infinity();  ///< world units, > 0
  const Interrupter* interrupter = nullptr;
};

/// Where the results of `count` points go; a null array is not computed.
struct PointResults {
  double* distance = nullptr;
  Vec3d* closest_point = nullptr;
  int64_t* feature = nullptr;
  Vec3d* gradient = nullptr;
};

Status queryPoints(const PointSearch& search, const Vec3d* at, size_t count, const PointQueryOptions& options,
                   const PointResults& out);

/// What the closest-feature id of these seeds names: "triangle", "point" or "voxel".
std::string_view pointFeatureName(SeedKind seeds);

}  // namespace distband
