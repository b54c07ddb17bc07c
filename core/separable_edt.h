// Separable exact EDT: the whole-grid distance field of a seed volume, computed axis by axis (Felzenszwalb &
// Huttenlocher's lower envelope of parabolas) and streamed like the band engine's output.
// Contract (the band engine's, core/engine.h, for the seeds it covers):
//   * Seeds: a dense mask on the grid (x fastest, nonzero = seed). Unsigned: each voxel's distance to the nearest
//     seed voxel centre (0 on the mask), exactly — scipy's distance_transform_edt(mask == 0) * voxel size. With
//     inside_negative: outside voxels +distance to the nearest mask voxel, mask voxels -distance to the nearest
//     non-mask voxel (the engine's signed volume).
//   * Whole grid, no limit: this is the algorithm a volume query without a limit picks (FieldPlan::algorithm); a
//     query with a limit stays a band computation, whose cost follows the band.
//   * Streaming: segments of options.segment_length_world, nearest first, each voxel delivered once in the segment
//     its |distance| falls in; bricks sorted by origin (z, y, x); chunks of options.max_chunk_bricks with the
//     last one marked complete; the final segment marked last. Segment 0 comes after the whole field is known:
//     the separable passes cannot finish near voxels before far ones (the price of the full-domain speed).
//   * Exact: squared distances are integers (voxel units), computed in 32-bit integers; values are
//     float(sqrt(d²) * voxel size).
//   * Threads: options.threads > 0 runs in a task_arena of that size, else in the caller's. The interrupter is
//     polled per slice or row in every pass and per brick range while emitting; an interrupted run returns
//     EngineResult::interrupted with what it delivered so far.
//   * Memory: 4 bytes per grid voxel (8 when signed), plus one chunk of output bricks.
// Errors (mask size, grid) throw std::invalid_argument, like the engine's preconditions.
#pragma once

#include <cstdint>
#include <vector>

#include "core/engine.h"
#include "core/grid.h"

namespace distband {

EngineResult computeSeparableVolumeField(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative,
                                         const EngineOptions& options, const SegmentCallback& on_segment);

}  // namespace distband
