// VolumeSearch: the exact distance from any point to a seed volume's nearest seed voxel centre, built once per volume
// on its lattice (the grid the volume's mask covers: voxel (i, j, k) at origin + voxel_size * (i, j, k)).
// Contract:
//   * A point whose nearest lattice point is a seed voxel lies in that voxel's cell: it is its nearest seed (one
//     lookup). Any other point's nearest seed is a boundary seed voxel — one with a 6-neighbour that is not a seed or
//     lies outside the grid (a nearer seed would otherwise lie one step towards the point) — so only those are
//     searched (core/points/point_set.h over their centres).
//   * Signed (inside_negative, the grid path's mask-inside: edt(mask == 0) - edt(mask != 0)): a point in a seed
//     voxel's cell gets minus its distance to the nearest non-seed voxel centre of the grid (searched among the
//     non-seed voxels with a seed 6-neighbour), every other point plus its distance to the nearest seed. At the voxel
//     centres this is the grid path's field exactly; the feature id is then the voxel across the boundary.
//   * nearest() gives the signed distance, the feature voxel's linear index (z * Y + y) * X + x and its centre; false
//     when that voxel lies farther than `limit` (whose sign inside() still tells).
//   * build() polls `interrupter`; kInvalidArgument for a mask of the wrong size, without a seed voxel, or (signed)
//     without a non-seed voxel.
// Immutable once built; nearest() is thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "core/grid.h"
#include "core/interrupter.h"
#include "core/points/point_set.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

struct NearestVoxel {
  double distance = 0;  ///< signed: negative inside the mask when inside_negative
  int64_t voxel = -1;   ///< linear index in the lattice
  Vec3d centre;
};

class VolumeSearch {
 public:
  static Status build(std::shared_ptr<const std::vector<uint8_t>> mask, const Grid& lattice, bool inside_negative,
                      const Interrupter* interrupter, VolumeSearch* out);

  /// The nearest feature within `limit` (world units, +infinity: none).
  bool nearest(const Vec3d& p, double limit, NearestVoxel* out) const;
  /// Whether p lies in a seed voxel's cell (negative when inside_negative).
  bool inside(const Vec3d& p) const { return seedCell(p).has_value(); }
  bool insideNegative() const { return inside_negative_; }
  const Grid& lattice() const { return lattice_; }

  uint64_t memoryBytes() const {
    return seeds_.memoryBytes() + (free_ ? free_->memoryBytes() : 0);  // the mask is the asset's
  }
  /// An upper bound on memoryBytes() and the build's peak for a volume with these boundary voxels (seeds, and free
  /// voxels next to a seed when signed).
  static uint64_t estimateBytes(uint64_t boundary_voxels) {
    return PointSet::estimateBytes(boundary_voxels) + boundary_voxels * sizeof(Vec3d);
  }

 private:
  /// The seed voxel whose cell holds p, if any.
  std::optional<int64_t> seedCell(const Vec3d& p) const;

  std::shared_ptr<const std::vector<uint8_t>> mask_;
  Grid lattice_;
  bool inside_negative_ = false;
  PointSet seeds_;                  ///< boundary seed voxels
  std::unique_ptr<PointSet> free_;  ///< signed: non-seed voxels next to a seed
};

}  // namespace distband
