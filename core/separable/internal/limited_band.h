// Separable band: the exact squared distances of the voxels within a limit of a seed volume, computed axis by axis
// like the whole-grid separable EDT, but only on the bricks that can hold them, so work and memory follow the band
// and not the grid. Internal to core (core/separable/volume_edt.cc streams its result).
// Contract:
//   * Seeds are the voxels whose mask test ((mask != 0) == seeds_nonzero) holds; targets are the others. For every
//     target within sqrt(cut2) voxels of a seed the result holds its exact squared distance to the nearest seed; every
//     other target holds kFarSquared (core/separable/internal/lines.h) or a value > cut2. Values at seed voxels are unspecified
//     (the caller knows them: 0, or the other side's distance when signed).
//   * Why it is exact: the nearest seed q of a target p has a 6-neighbour that is no seed (step from q towards p
//     along an axis where they differ: that voxel is closer to p, so it is no seed). Such seeds lie in bricks that are
//     mixed or next to a brick that is not all seeds; the passes use the seeds of those bricks only, and a squared
//     distance is a sum of the passes' non-negative terms, so values beyond cut2 can be dropped after every pass.
//   * Work: the mask is read once, a machine word per brick row, to classify bricks; then three line passes (x, y,
//     z), each over the previous pass's bricks grown by ceil(sqrt(cut2) / 8) bricks along its axis: with a limit of
//     L voxels, O(boundary bricks x (1 + 2L/8)^(1..3)) brick visits. Memory: 2 KiB per brick that holds a value
//     (bricks the growth adds are worked on in per-thread scratch and kept only if they got one), carved from
//     per-thread slabs of 64 KiB doubling to 2 MiB (at most twice the bricks held, plus 64 KiB a thread), plus one
//     byte per brick of the grid for the classification.
//   * Deterministic (the same result for any thread count); runs in the caller's TBB arena. The interrupter is polled
//     per brick slab and per run of bricks; an interrupted call returns false.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/grid.h"
#include "core/interrupter.h"

namespace distband::separable_internal {

/// Bricks with their squared distances: keys ascending (Grid::brickIndex, i.e. (z, y, x) order of the origins),
/// values[i] holds kBrickVoxels entries in brickOffset order.
struct SquaredBricks {
  std::vector<uint64_t> keys;
  std::vector<const uint32_t*> values;
  std::vector<std::shared_ptr<void>> storage;  ///< owns the memory `values` point into
  /// values[i] for brick key `key`, or null when it is not listed. O(log n).
  const uint32_t* find(uint64_t key) const;
};

/// What a brick of the grid holds of the mask (of its voxels inside the grid).
enum MaskBrick : uint8_t { kNoMaskVoxel = 0, kAllMaskVoxels = 1, kSomeMaskVoxels = 2 };

/// One MaskBrick per brick of the grid, by Grid::brickIndex.
std::vector<uint8_t> classifyMaskBricks(const Grid& grid, const std::vector<uint8_t>& mask,
                                        const Interrupter* interrupter);

/// See above. `brick_kinds` from classifyMaskBricks; `cut2` >= 0. False when interrupted.
bool squaredDistancesWithin(const Grid& grid, const std::vector<uint8_t>& mask,
                            const std::vector<uint8_t>& brick_kinds, bool seeds_nonzero, uint32_t cut2,
                            const Interrupter* interrupter, SquaredBricks* out);

}  // namespace distband::separable_internal
