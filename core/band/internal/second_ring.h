// The second-ring correction (exact mode). Vector propagation can leave a voxel with a site that is not its closest
// where different sites meet: its true closest site may be held by none of its stencil neighbours. Such a voxel
// tries every site held within Chebyshev distance 2. Which voxels are checked is decided by the field alone, so the
// result does not depend on thread timing:
//   * the first round of a segment checks every voxel of the segment at a site boundary (scanAndCheck);
//   * later rounds check only boundary voxels within distance 2 of a voxel changed since the last round.
// Contract: correct() is called by the run loop when a segment's front is empty (BandState::collect_dirty false for
// the first round); it applies the corrections found and returns them as the next front. The other functions are
// its parts, exposed for unit tests. All run TBB loops internally except the const per-voxel helpers.
#pragma once

#include "core/band/internal/band_state.h"

namespace distband::band_internal {

/// One correction round; returns the corrected voxels that propagate, as the next front.
FrontList correct(BandState& s, bool first_round);

/// A voxel may hold a site that is not its closest only where different sites meet: true when a propagating
/// stencil neighbour (same region) of voxel q (key k) holds a different site.
bool isBoundary(const BandState& s, const Coord& q, uint64_t k);
/// Records in the threads' corrections every boundary voxel of the pending bricks (within the segment's threshold,
/// not yet delivered) for which a site held within distance 2 is better.
void scanAndCheck(BandState& s);
/// Tries every site held within Chebyshev distance 2 of voxel v (at q, key k); a better one is recorded as a
/// correction in tb. `block` is scratch for 125 keys.
void checkVoxel(const BandState& s, const VoxelRef& v, const Coord& q, uint64_t k, uint64_t* block, ThreadBuffers& tb);
/// Keys of the 5^3 block centred on q (index (dz+2)*25 + (dy+2)*5 + (dx+2)); kUntouched outside the grid, in
/// another region, untouched, or holding no site.
void gatherBlock(const BandState& s, const Coord& q, uint64_t* block);

}  // namespace distband::band_internal
