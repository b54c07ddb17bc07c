// Separable exact EDT: the distance field of a seed or label volume, computed axis by axis (Felzenszwalb &
// Huttenlocher's lower envelope of parabolas) and streamed like the band engine's output.
// Contract (the band engine's, core/band/band_engine.h, for the seeds it covers):
//   * Input: a LabelVolume on the grid (core/seeds/label_volume.h: uint8, uint16 or uint32, x fastest). What is
//     measured (VolumeMeasure, core/seeds/volume_seeds.h, decided by the planner, core/field/field_plan.h):
//       - the seed field: seeds are the nonzero voxels. Unsigned: each voxel's distance to the nearest seed voxel
//         centre (0 on a seed) — scipy's distance_transform_edt(volume == 0, sampling=spacing). With inside_negative:
//         outside voxels +distance to the nearest seed, seeds -distance to the nearest zero voxel. With
//         options.closest_features each delivered voxel's closest feature (Brick::closest) is the label of its
//         nearest seed (a seed's own label; scipy's return_indices looked up in the volume; among equidistant seeds
//         the lower label).
//       - the multi-label EDT (labels = true, seung-lab edt's edt::edt): a voxel of label L != 0 gets its distance to
//         the nearest voxel whose label differs from L; label 0 voxels get 0. With black_border the voxels just
//         outside the grid count as label 0.
//   * Distances are in world units with the grid's spacing per axis (core/grid.h): the passes run in unit space,
//     each axis weighted by its squared scale. On a cubic grid squared distances are integers (voxel units) in
//     32-bit integers, values float(sqrt(d²) * voxel size) — exact; on an anisotropic one they are floats summed in
//     double and rounded once per pass (relative error ~1e-7).
//   * This is the algorithm every exact-mode volume query picks (FieldPlan::algorithm). Without a limit it runs over
//     the whole grid. With options.limit_world it delivers exactly the voxels whose |distance| <= the limit (label-0
//     voxels of the multi-label EDT and the seeds of an unsigned seed field: all of them, at 0), and its work and
//     memory follow them: the passes run only over the bricks of the boundaries grown by the limit
//     (core/separable/internal/limited_band.h), after one read of the volume.
//   * Streaming: segments of options.segment_length_world, nearest first, each voxel delivered once in the segment
//     its |distance| falls in (the last one's upper bound is the limit); bricks sorted by origin (z, y, x); chunks
//     of options.max_chunk_bricks with the last one marked complete; the final segment marked last. Near field
//     first: the separable passes cannot finish near voxels before far ones, so
//       - with a limit and chunks, the limit's band is computed in two parts along z: the first brick layers holding
//         a boundary (up to ~1/32 of the band's boundary bricks), whose segment-0 chunks are streamed at once, then
//         the rest (the layers within the limit of the cut are read by both), then segment 0's other chunks and the
//         later segments — the first bricks after a few percent of the run, at the cost of the cut's reach;
//       - otherwise, when there is more than one segment (and, with a limit, the limit reaches at least four times as
//         many bricks as a segment) segment 0 is computed first by the band within its bound and streamed, then the
//         rest (whole grid or the limit's band). When nothing lies past segment 0, an empty segment 1 marks the end.
//   * Threads: options.threads > 0 runs in a task_arena of that size, else in the caller's. The result is
//     bit-identical for any thread count. The interrupter is polled per slice, row or run of bricks in every pass
//     and per brick range while emitting; an interrupted run returns FieldRunResult::interrupted with what it
//     delivered so far.
//   * Memory: whole grid, 4 bytes per grid voxel (8 when signed or with nearest labels); with a limit, 2 KiB per
//     visited brick (twice when signed or with nearest labels) and five bytes per grid brick; plus one chunk of output
//     bricks. Near field first: the first segment's band is freed before the rest is computed (nothing added to the
//     peak); the two parts of a limit's band add the bricks of the layers within the limit of the cut, which both
//     compute. FieldRunResult::bricks_allocated counts the bricks holding distances in the last band computed: the
//     limit's (both parts' own), or without a limit the first segment's when the near field came first (0
//     otherwise).
// Errors (the volume's dims, the grid, checkVolumeMeasure's conditions, a limit that is not > 0, closest features of
// the multi-label EDT) throw std::invalid_argument, like the engine's preconditions.
#pragma once

#include <cstdint>
#include <vector>

#include "core/field/field_run.h"
#include "core/grid.h"
#include "core/seeds/label_volume.h"
#include "core/seeds/volume_seeds.h"

namespace distband {

FieldRunResult computeSeparableVolumeField(const Grid& grid, const LabelVolume& volume, const VolumeMeasure& measure,
                                           const FieldRunOptions& options, const SegmentCallback& on_segment);

}  // namespace distband
