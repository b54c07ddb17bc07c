// gridForMesh: the Grid a mesh's distance field is computed on.
// Contract: exactly one of three ways to size it (checked):
//   * voxel_size H: voxels of size H, the mesh's bounding box plus `padding_voxels` on every side;
//   * resolution N: the paper's "volume size" N^3 — the longest side of the padded box spans exactly N voxels
//     (so H = longest extent / (N - 1 - 2 * padding)); the other axes get as many voxels as they need;
//   * an explicit world box [box_min, box_max] with voxel size H or resolution N along its longest side.
// The origin is box_min - padding * H, so two grids with the same H and integer paddings share one lattice.
// Returns "" or a message naming the option and the rule it breaks. Pure function.
#pragma once

#include <optional>
#include <string>

#include "core/grid.h"
#include "core/mesh/triangle_mesh.h"

namespace distband {

struct MeshGridOptions {
  double voxel_size = 0;   ///< > 0 selects sizing by voxel size
  int resolution = 0;      ///< > 0 selects sizing by the longest side (mutually exclusive with voxel_size)
  int padding_voxels = 3;  ///< margin on every side, in voxels (>= 0)
  /// Explicit world box instead of the mesh's bounding box (padding still applies).
  std::optional<Vec3d> box_min, box_max;
};

std::string gridForMesh(const TriangleMesh& mesh, const MeshGridOptions& options, Grid* grid);

}  // namespace distband
