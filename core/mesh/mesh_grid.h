// gridForMesh: the Grid a mesh's distance field is computed on.
// Contract: exactly one of three ways to size it (checked):
//   * voxel_size H: voxels of size H, the mesh's bounding box plus `padding_voxels` on every side;
//   * resolution N: the paper's "volume size" N^3 — the longest side of the padded box spans exactly N voxels
//     (so H = longest extent / (N - 1 - 2 * padding)); the other axes get as many voxels as they need;
//   * an explicit world box [box_min, box_max] with voxel size H or resolution N along its longest side.
// The origin is box_min - padding * H, so two grids with the same H and integer paddings share one lattice.
// Padding: this is the one place its default is decided. Around the seeds' bounds it is at least
// kDefaultPaddingVoxels and at least the limit in voxels (so the band is never clipped at the grid's faces); with a
// resolution, the padding it takes is capped so the bounds keep at least half of the N voxels (then the band is
// clipped, and the result says so). Around an explicit box the default is 0 (the box is the region asked for).
// An explicit padding wins; `band_clipped` reports when it is smaller than the limit.
// Returns OK or kInvalidArgument naming the option and the rule it breaks. Pure function.
#pragma once

#include <limits>
#include <optional>
#include <string>

#include "core/grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/status.h"

namespace distband {

inline constexpr int kDefaultPaddingVoxels = 3;
inline constexpr int kMaxPaddingVoxels = kMaxGridDim / 4;

struct MeshGridOptions {
  double voxel_size = 0;   ///< > 0 selects sizing by voxel size
  int resolution = 0;      ///< > 0 selects sizing by the longest side (mutually exclusive with voxel_size)
  /// Margin on every side, in voxels, in [0, kMaxPaddingVoxels]. Unset: the default described above.
  std::optional<int> padding_voxels;
  /// Explicit world box instead of the mesh's bounding box (padding still applies).
  std::optional<Vec3d> box_min, box_max;
};

/// What gridForMesh decided besides the grid.
struct GridPadding {
  int voxels = 0;             ///< the padding used
  bool band_clipped = false;  ///< fitted around the bounds with a padding below the limit in voxels
};

/// `limit`: the request's distance limit (FieldRequest::limit()), which the default padding holds.
Status gridForMesh(const TriangleMesh& mesh, const MeshGridOptions& options, const DistanceLimit& limit, Grid* grid,
                   GridPadding* padding = nullptr);

}  // namespace distband
