// Band extent: a cheap upper bound on the voxels a run of the engine touches, for admission before any work.
// Contract:
//   * BandExtent marks the seeds' positions on a coarse grid of cells (whole bricks, coarser on huge grids so the
//     cell grid stays <= ~2 M cells), grows the marks by the limit plus the engine's reach (Chebyshev distance in
//     cells, which contains every voxel within Euclidean distance limit of a seed), and counts the grid voxels in
//     marked cells. The engine allocates whole 8^3 bricks only where it offers distances, i.e. within the limit
//     plus its admission slack of a seed, so voxelBound() >= the voxels of the bricks it allocates.
//   * Seeds outside the grid are projected onto it (projection onto a box never increases a distance to a voxel
//     inside it), and ignored when farther than the reach.
//   * Without a limit (or when the reach covers the grid) the bound is the grid's voxel count, at no cost.
//   * Cost: O(seeds + cells); memory: one byte per cell.
// VolumeFootprint summarises a seed mask once (at upload): how many seed and boundary voxels it has and which
// bricks hold them, so a query's bound and seed memory are known without rescanning the mask.
// Not synchronised; plain values.
#pragma once

#include <cstdint>
#include <vector>

#include "core/grid.h"
#include "core/seeds/label_volume.h"
#include "core/seeds/volume_seeds.h"
#include "core/interrupter.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

/// Voxels beyond the limit the engine may still allocate: its admission slack (1 voxel), a stencil link (<= 2)
/// and the initial mesh band (1.5 voxels).
inline constexpr double kEngineReachVoxels = 4.0;

class BandExtent {
 public:
  BandExtent(const Grid& grid, double limit_voxels);

  /// True when the bound is the whole grid whatever the seeds (no limit, or a limit that reaches everywhere).
  bool wholeGrid() const { return whole_grid_; }
  /// An index-space point (e.g. a point seed or a voxel).
  void addPoint(const Vec3d& p);
  /// An index-space axis-aligned box (e.g. a triangle's bounds).
  void addBox(const Vec3d& lo, const Vec3d& hi);
  /// The voxel box [lo, hi] (inclusive, index space).
  void addVoxelBox(const Coord& lo, const Coord& hi);

  /// Upper bound on the voxels the engine touches (0 when nothing was added and the bound is not the whole grid).
  uint64_t voxelBound() const;
  int cellSize() const { return cell_; }

 private:
  Grid grid_;
  double reach_ = 0;
  bool whole_grid_ = false;
  int cell_ = 8;
  Coord cells_{};
  std::vector<uint8_t> marked_;
};

/// What a seed or label volume (core/seeds/label_volume.h; nonzero = seed) holds.
struct VolumeFootprint {
  Coord dims{};
  uint64_t seed_voxels = 0;      ///< nonzero voxels
  uint64_t boundary_voxels = 0;  ///< voxels with a 6-neighbour on the other side (both sides counted)
  uint64_t label_boundary_voxels = 0;  ///< voxels with a 6-neighbour of another label
  Coord bricks{};                ///< brick grid of `dims`
  /// Per brick, x fastest: bit 0 = holds a seed voxel, bit 1 = a boundary voxel, bit 2 = a label boundary voxel.
  std::vector<uint8_t> brick_flags;

  static constexpr uint8_t kSeed = 1, kBoundary = 2, kLabelBoundary = 4;
  uint64_t memoryBytes() const { return brick_flags.size() + sizeof(*this); }
};

/// Scans `volume` once (polling `interrupter`).
Status analyzeVolume(const LabelVolume& volume, const Interrupter* interrupter, VolumeFootprint* out);

/// Adds a volume's seeds to `extent`: the bricks holding seed voxels (the unsigned seed field), boundary voxels
/// (signed: voxels deeper inside or outside than the limit are never reached) or label boundary voxels (the
/// multi-label EDT).
void addVolume(const VolumeFootprint& volume, const VolumeMeasure& measure, BandExtent* extent);

}  // namespace distband
