// PointPlan: the one place the choices of a point query are made, for every caller — the server's QueryPoints, the
// coordinator, `distband at` and the benches — and the search they imply.
// Contract:
//   * planPoints() turns a FieldRequest (the same request type the grid path plans: seeds, sign, limit; its grid,
//     stencil, mode, segment and algorithm fields do not apply and must be unset) into a PointPlan: the sign by
//     planSign (the grid path's rule: auto = pseudonormal for a closed mesh whose parts do not overlap, winding
//     otherwise), the limit in world units (limit_voxels reads the volume's lattice, the only grid a point query has),
//     and the sign of the points beyond the limit (farSign). kInvalidArgument naming the field otherwise.
//   * completePointSearch() builds every part of a PointSearch the plan needs and `search` lacks: a caller that keeps
//     parts (the server's asset cache) fills them in first and keeps what was built; the parts are immutable and
//     shared. Meshes: a TriangleBvh, a MeshSign of the plan's method in world space, a winding-number MeshSign for
//     the points beyond a finite limit when the method is pseudonormal; points: a PointSet; volumes: a VolumeSearch.
//     It polls `interrupter` (then returns its status).
//   * pointSearchBytes() bounds the peak bytes of what completePointSearch would build (admission, before any work),
//     and the bytes a built part holds.
// Pure functions; thread-safe.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/field/field_plan.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/point_query.h"
#include "core/status.h"

namespace distband {

struct PointPlan {
  SeedKind seeds = SeedKind::kMesh;
  SignMethod mesh_sign = SignMethod::kUnsigned;  ///< meshes: the method in force (never kAuto)
  bool inside_negative = false;                  ///< volumes
  std::string sign_reason;
  double limit_world = std::numeric_limits<double>::infinity();

  bool signedField() const {
    return seeds == SeedKind::kMesh ? mesh_sign != SignMethod::kUnsigned : seeds == SeedKind::kVolume && inside_negative;
  }
  /// "pseudonormal", "winding", "parity", "mask-inside" or "unsigned".
  std::string_view signName() const;
  /// The mesh sign that signs the points beyond the limit when mesh_sign cannot (pseudonormal needs a closest
  /// triangle): kWinding; kUnsigned when none is needed.
  SignMethod farSign() const;
  PointQueryOptions queryOptions(const Interrupter* interrupter) const {
    return {limit_world, interrupter};
  }
};

/// `mesh_report` for meshes (the automatic sign reads its edges), `lattice` for volumes, else null.
Status planPoints(const FieldRequest& request, const MeshReport* mesh_report, const Grid* lattice, PointPlan* out);

/// The seeds a point search is built from; the one matching the plan's seeds is read.
struct PointSeedSource {
  const TriangleMesh* mesh = nullptr;       ///< world units, validated
  const std::vector<Vec3d>* points = nullptr;
  std::shared_ptr<const std::vector<uint8_t>> mask;  ///< on `lattice`, x fastest
  Grid lattice;
};

Status completePointSearch(const PointPlan& plan, const PointSeedSource& source, const Interrupter* interrupter,
                           PointSearch* search);

/// Seed counts that size a search (what the seeds' sizes are, known before any part is built).
struct PointSeedCounts {
  uint64_t mesh_vertices = 0, mesh_triangles = 0;
  uint64_t points = 0;
  uint64_t volume_boundary_voxels = 0;  ///< seed voxels next to a non-seed or a face, plus (signed) the reverse
};
/// Peak bytes of building the parts of the plan's search that `have` lacks.
uint64_t pointSearchBytes(const PointPlan& plan, const PointSeedCounts& counts, const PointSearch& have);

}  // namespace distband
