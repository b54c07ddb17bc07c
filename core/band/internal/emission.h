// Emission: hands a finished segment's voxels to the consumer as output bricks, sorted by origin (z, y, x).
// Contract: called by the run loop at the end of each segment (collectPending also by the second ring). Bricks of
// BandState::pending_bricks deliver their touched, not yet delivered voxels within BandState::thr2, marked emitted;
// those still holding voxels beyond it stay pending. In the last segment the engine's bricks are freed as their
// output is built. Runs TBB loops internally; the callback runs on the calling thread.
#pragma once

#include <cstdint>
#include <vector>

#include "core/band/internal/band_state.h"

namespace distband::band_internal {

/// Merges the bricks that got their first unemitted voxel into BandState::pending_bricks, kept sorted by origin
/// (z, y, x). (Millions of bricks on large grids: sorted in parallel, and stoppable.)
void collectPending(BandState& s);

/// Delivers every touched voxel within the threshold not delivered before, as one callback or (max_chunk_bricks) in
/// chunks. Returns whether this was the last segment: the limit was reached, or nothing was deferred and no admitted
/// voxel waits beyond the threshold. `lower_vox`, `upper_vox`: the segment's range (for the SegmentBricks).
bool emitSegment(BandState& s, const SegmentCallback& cb, int index, double lower_vox, double upper_vox,
                 bool nothing_deferred, SegmentStats& stats);

/// Builds the output bricks of pending bricks [c0, c1) into `out` (out[slot - 1 - base]) and marks them delivered.
/// slot[i]: 1 + the position of pending brick i in the segment's output, or 0; keep[i]: it stays pending.
void buildChunk(BandState& s, size_t c0, size_t c1, const std::vector<uint32_t>& slot,
                const std::vector<uint8_t>& keep, uint32_t base, std::vector<Brick>& out);

/// The closest-feature id of a delivered voxel holding `site` (kNoSite for none; see Seeds::FeatureKind).
int64_t closestFeature(const BandState& s, uint32_t site, const Coord& voxel);

/// Frees every brick; hands large amounts back to the system (see the definition).
void releaseBricks(BandState& s);

}  // namespace distband::band_internal
