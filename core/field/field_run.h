// Field run: the streaming contract every distance-field algorithm serves (the band, core/band/band_engine.h; the
// separable EDTs, core/separable/), and the options and result they share.
// Contract of a run (computeField, core/field/compute_field.h, or an algorithm's own entry point):
//   * Segments: segment i delivers the voxels whose |distance| lies in (i*L, (i+1)*L] (segment 0 includes 0), L =
//     segment_length_world (0: one segment up to the limit), nearest first. Every voxel within the limit that the
//     algorithm reaches is delivered exactly once, in the segment its value falls in; delivered values are final.
//     Nothing beyond limit_world is delivered. The last segment is marked `last`; its upper bound is the limit.
//   * Bricks of a segment are sorted by origin (z, y, x); each brick's mask marks the voxels it delivers.
//   * Chunks: with max_chunk_bricks = N > 0 a segment is handed over in chunks of at most N bricks, in (z, y, x)
//     order, the last one marked `complete` (it may be empty); the next chunk is built only after the callback
//     returned, so a callback that blocks pauses the run. N = 0: one callback per segment.
//   * The callback runs on the calling thread.
//   * Threads: threads > 0 runs the compute in a TBB task_arena of that size, otherwise in the caller's arena. The
//     result is bit-identical for any thread count.
//   * Interruption: `interrupter` is polled in every phase, so a stop request ends the run within ~10 ms of work on
//     each thread; the run then returns FieldRunResult::interrupted = true (chunks already delivered stay valid,
//     nothing more is delivered).
//   * closest_features: each delivered voxel's closest feature too (Brick::closest; what the ids mean:
//     Seeds::FeatureKind, core/seeds/seeds.h).
// Plain values; validateRunOptions is pure.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "core/brick.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

struct FieldRunOptions {
  double segment_length_world = 0;                               ///< 0: a single segment
  double limit_world = std::numeric_limits<double>::infinity();  ///< distance limit (world units)
  int threads = 0;                                               ///< 0: the caller's TBB arena
  const Interrupter* interrupter = nullptr;                      ///< polled in every phase; may be null
  size_t max_chunk_bricks = 0;  ///< > 0: hand segments over in chunks of at most this many bricks
  bool closest_features = false;
};

struct SegmentStats {
  int index = 0;
  double lower_world = 0, upper_world = 0;
  int64_t voxels = 0;  ///< voxels delivered
  int64_t bricks = 0;  ///< brick messages delivered
  int steps = 0;       ///< propagation steps in this segment (the band; 0 for the separable EDTs)
  double seconds = 0;  ///< compute time of the segment (excluding the callback)
};

struct FieldRunResult {
  bool interrupted = false;
  int64_t voxels = 0;  ///< voxels delivered
  double seconds = 0;
  /// After the run: freeing its state. Part of a stopped run's time to return, but not compute: it grows with the
  /// memory held (about 0.1 s a GiB on the 2-core development VM).
  double release_seconds = 0;
  std::vector<SegmentStats> segments;
  // Work measures of the band (core/band/band_engine.h); the separable EDTs leave them 0 except bricks_allocated.
  int steps = 0;
  int64_t updates = 0;          ///< accepted site updates
  int64_t corrections = 0;      ///< voxels improved by the second-ring correction
  int64_t bricks_allocated = 0;  ///< bricks of state held at the end
  SignShares sign_shares;        ///< signed mesh fields: how the delivered voxels were signed (computeField)
};

using SegmentCallback = std::function<void(SegmentBricks&&)>;

/// OK when `grid` is valid and the options are usable with it (finite segment length >= 0, limit > 0, threads in
/// [0, 4096], at most 100000 segments); else kInvalidArgument naming the field and the rule.
Status validateRunOptions(const Grid& grid, const FieldRunOptions& options);

}  // namespace distband
