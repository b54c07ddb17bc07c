// Propagation: the vector propagation of closest sites over the band, step by step (SMI 2009's adaptive iteration).
// A step is Jacobi-like: every voxel that changed in the previous step offers the site it held at the end of that
// step (snapshotted in the front list) to its stencil neighbours; neighbours keep the minimum key. Pushes from voxels
// that did not change would repeat offers already made, so only changed voxels work (the paper's band iteration gives
// the same field; the lifespan then only decides when a voxel stops accepting offers).
// Contract: called by the run loop (BandRun) between its other phases; each function runs its own TBB parallel loop
// and polls BandState::stopping(). Offers beyond BandState::admit2 are held back in the threads' deferred lists
// (when BandState::defer), to be replayed by takeDeferred().
#pragma once

#include "core/band/internal/band_state.h"

namespace distband::band_internal {

// Offers are admitted this many voxels beyond a segment's threshold, while only voxels within the threshold are
// frozen and delivered: a closest site whose path briefly runs outside the threshold still arrives. At the limit the
// slack is smaller: it is paid in work and memory on every query, and nothing beyond the limit is delivered.
inline constexpr double kAdmitSlackVoxels = 2.0;
inline constexpr double kLimitSlackVoxels = 1.0;

/// Offers `newkey` to voxel `off` of brick `b` (id `bi`). Returns true when it lowered the voxel's key; then lists
/// the brick for emission if this was its first touch, the voxel as dirty (collect_dirty), and (`propagates`) the
/// voxel in the next front.
bool offer(BandState& s, BrickState* b, uint32_t bi, int off, uint64_t newkey, bool propagates, ThreadBuffers& tb);

/// Offers the site of front entry `e` to its stencil neighbours.
void pushFrom(BandState& s, const FrontEntry& e, ThreadBuffers& tb);

/// Step 0: writes the band's keys (voxels beyond the limit's admission are skipped). Throws std::invalid_argument
/// for band voxels outside the grid or naming a site out of range, or too many sites.
void insertBand(BandState& s);
/// The first step of an exact band, pushed from the band list itself. With `give_back_band` (the caller owns the band
/// and frees it after this step) the band's pages are given back as they are read: nothing may read it afterwards.
void stepFromBand(BandState& s, bool give_back_band);
/// One step: every entry of `front` pushes.
void step(BandState& s, const FrontList& front);
/// The voxels changed in the last step, each with its site and arrival direction as of now: the next front, written
/// over `front` (whose storage is reused, as are the threads' lists it empties). Empty when the run must stop.
void gatherFront(BandState& s, FrontList& front);
/// Room for `entries` in the threads' next lists together (each thread a share), kept if they have it.
void reserveNext(BandState& s, size_t entries);
/// Gives back the storage gatherFront keeps between steps: `front`'s and the threads' next lists'.
void releaseFronts(BandState& s, FrontList& front);
/// Moves the threads' held-back offers into BandState::deferred; false when the run must stop.
bool collectDeferred(BandState& s);
/// Held-back offers (this step's and earlier ones) as the next front. Not deduplicated: an offer two threads made
/// for the same voxel in one step (both listed it) is replayed twice, which changes nothing.
FrontList takeDeferred(BandState& s);
/// Paper mode: voxels admitted beyond the previous threshold but not yet delivered start the new segment's
/// lifespan clock.
void rearmLifespans(BandState& s);

}  // namespace distband::band_internal
