// Separable band: the exact squared distances of the voxels within a limit, computed axis by axis like the whole-grid
// separable EDT, but only on the bricks that can hold them, so work and memory follow the band and not the grid.
// Internal to core (core/separable/volume_edt.cc streams its result).
// Contract:
//   * What is measured (BandMeasure): the seed field — seeds are the voxels whose test ((label != 0) == seeds_nonzero)
//     holds, targets the others, and each target gets its squared distance to the nearest seed (nearest-label cells:
//     tagged with that seed's label) —, or the multi-label EDT — each voxel of label L != 0 gets its squared distance
//     to the nearest voxel of another label (or, with black_border, of the grid's outside). For every target within
//     sqrt(cut2) units (core/grid.h) of what it measures to, the result holds its exact cell; every other target holds
//     far or a value > cut2. Values at seed voxels (label-0 voxels of the multi-label EDT) are unspecified: the caller
//     knows them.
//   * Squared distances are in unit space: cells of core/separable/internal/lines.h (uint32_t on a cubic grid, float
//     on an anisotropic one, Tagged for nearest labels), each axis weighted by its squared scale `w2`.
//   * Why it is exact: what a target p measures to, q, has a 6-neighbour that is of p's kind (step from q towards p
//     along an axis where they differ: that voxel is closer to p, so it is no seed, or of p's label). Such q lie in
//     bricks that are mixed or next to a brick that differs (BrickClasses); the passes start from those bricks (the
//     multi-label passes read labels along the whole line, so every run end within reach is seen), and a squared
//     distance is a sum of the passes' non-negative terms, so values beyond cut2 can be dropped after every pass.
//   * Work: the volume is read once to classify bricks; then three line passes (x, y, z), each over the previous
//     pass's bricks grown along its axis by the reach (sqrt(cut2) / the axis scale, in bricks): with a limit of L
//     voxels, O(boundary bricks x (1 + 2L/8)^(1..3)) brick visits. Memory: a brick of cells per brick that holds a
//     value (bricks the growth adds are worked on in per-thread scratch and kept only if they got one), carved from
//     per-thread slabs of 64 KiB doubling to 2 MiB (at most twice the bricks held, plus 64 KiB a thread), plus five
//     bytes per brick of the grid for the classification.
//   * Deterministic (the same result for any thread count); runs in the caller's TBB arena. The interrupter is polled
//     per brick slab and per run of bricks; an interrupted call returns false.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "core/grid.h"
#include "core/interrupter.h"
#include "core/separable/internal/lines.h"

namespace distband::separable_internal {

/// Bricks with their cells: keys ascending (Grid::brickIndex, i.e. (z, y, x) order of the origins), values[i] holds
/// kBrickVoxels cells in brickOffset order.
template <class C>
struct CellBricks {
  std::vector<uint64_t> keys;
  std::vector<const C*> values;
  std::vector<std::shared_ptr<void>> storage;  ///< owns the memory `values` point into
  /// values[i] for brick key `key`, or null when it is not listed. O(log n).
  const C* find(uint64_t key) const;
};

/// What a brick of the grid holds (of its voxels inside the grid): for the seed field whether its labels are all zero,
/// all nonzero or some of each; for the multi-label EDT whether they are all one label (which) or several.
enum MaskBrick : uint8_t { kNoMaskVoxel = 0, kAllMaskVoxels = 1, kSomeMaskVoxels = 2 };
struct BrickClasses {
  std::vector<uint8_t> mask;      ///< MaskBrick per brick (Grid::brickIndex) of the test label != 0
  std::vector<uint8_t> uniform;   ///< multi-label only: 1 when every voxel of the brick has one label
  std::vector<uint32_t> label;    ///< multi-label only: that label
};

/// Classifies every brick of `grid` from `labels` (grid.voxelCount() elements, x fastest); `multi_label` adds the
/// uniform-label classes. Polls `interrupter` per line of bricks.
template <class T>
BrickClasses classifyBricks(const Grid& grid, const T* labels, bool multi_label, const Interrupter* interrupter);

/// What the band measures (see the contract).
struct BandMeasure {
  bool multi_label = false;
  bool seeds_nonzero = true;  ///< seed field: seeds are the nonzero voxels (false: the zero ones, a signed inside)
  uint8_t black_border = 0;   ///< multi-label: the faces beyond which the outside is label 0 (VolumeMeasure's)
};

/// A range of brick layers along z, [lo, hi) (Grid::brickDims().z): the part of the band a call computes.
struct BrickLayers {
  int lo = 0;
  int hi = std::numeric_limits<int>::max();
};

/// See above. `classes` from classifyBricks; `cut2` >= 0 (squared units); `w2`: the squared axis scales. Only the
/// bricks of `layers` are computed and listed (exact there: the passes read the layers within the reach beyond it,
/// so splitting a band into layer ranges costs the bricks those reaches visit twice). False when interrupted.
template <class C, class T>
bool cellsWithin(const Grid& grid, const T* labels, const BrickClasses& classes, const BandMeasure& measure,
                 typename CellOps<C>::Dist cut2, const double w2[3], const Interrupter* interrupter, CellBricks<C>* out,
                 BrickLayers layers = {});

/// The bricks the passes start from (see the contract: those holding a boundary of what `measure` measures), counted
/// per layer along z: where a band's work lies, to split it.
std::vector<int64_t> boundaryBricksPerLayer(const Grid& grid, const BrickClasses& classes, const BandMeasure& measure);

/// The brick layers along z within `cut2` (squared units) of a layer, with the axis's squared scale `w2z`: how far
/// the band of a layer range reaches beyond it.
int reachLayers(double cut2, double w2z);

}  // namespace distband::separable_internal
