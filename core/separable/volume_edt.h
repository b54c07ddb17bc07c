// Separable exact EDT: the distance field of a seed volume, computed axis by axis (Felzenszwalb & Huttenlocher's
// lower envelope of parabolas) and streamed like the band engine's output.
// Contract (the band engine's, core/band/band_engine.h, for the seeds it covers):
//   * Seeds: a dense mask on the grid (x fastest, nonzero = seed). Unsigned: each voxel's distance to the nearest
//     seed voxel centre (0 on the mask), exactly — scipy's distance_transform_edt(mask == 0) * voxel size. With
//     inside_negative: outside voxels +distance to the nearest mask voxel, mask voxels -distance to the nearest
//     non-mask voxel (the engine's signed volume).
//   * This is the algorithm every exact-mode volume query picks (FieldPlan::algorithm). Without a limit it runs over
//     the whole grid. With options.limit_world it delivers exactly the voxels whose |distance| <= the limit, and its
//     work and memory follow them: the passes run only over the bricks of the mask's boundary grown by the limit
//     (core/separable/internal/limited_band.h), after one word-per-brick-row read of the mask.
//   * Streaming: segments of options.segment_length_world, nearest first, each voxel delivered once in the segment
//     its |distance| falls in (the last one's upper bound is the limit); bricks sorted by origin (z, y, x); chunks
//     of options.max_chunk_bricks with the last one marked complete; the final segment marked last. Segment 0 comes
//     after the whole field is known: the separable passes cannot finish near voxels before far ones.
//   * Exact: squared distances are integers (voxel units), computed in 32-bit integers; values are
//     float(sqrt(d²) * voxel size). A voxel is within the limit when d² <= (limit / voxel size)².
//   * Threads: options.threads > 0 runs in a task_arena of that size, else in the caller's. The result is
//     bit-identical for any thread count. The interrupter is polled per slice, row or run of bricks in every pass
//     and per brick range while emitting; an interrupted run returns FieldRunResult::interrupted with what it
//     delivered so far.
//   * Memory: whole grid, 4 bytes per grid voxel (8 when signed); with a limit, 2 KiB per visited brick (twice when
//     signed) and a byte per grid brick; plus one chunk of output bricks. FieldRunResult::bricks_allocated counts the
//     bricks holding squared distances at the end (with a limit).
// Errors (mask size, grid, a limit that is not > 0) throw std::invalid_argument, like the engine's preconditions.
#pragma once

#include <cstdint>
#include <vector>

#include "core/field/field_run.h"
#include "core/grid.h"

namespace distband {

FieldRunResult computeSeparableVolumeField(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative,
                                         const FieldRunOptions& options, const SegmentCallback& on_segment);

}  // namespace distband
