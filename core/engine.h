// Engine: the adaptive iteration on an evolving active band (SMI 2009), segment by segment.
// Contract:
//   computeDistanceField(grid, seeds, options, on_segment) propagates closest sites from seeds.band over the
//   grid and hands every finished segment's bricks to `on_segment`, nearest first, on the calling thread.
//   * Segment i delivers the voxels whose |distance| lies in (i*L, (i+1)*L] (segment 0 includes 0), L =
//     options.segment_length (0: one segment up to the limit). Every voxel reached with |distance| <= limit is
//     delivered exactly once, in the segment its value falls in; values delivered in a segment are final. (Rarely
//     a voxel is first reached only in a later segment, with a value below that segment's lower bound: it is
//     delivered there.) Nothing beyond the limit is delivered; the engine computes at most one voxel beyond it
//     (the admission slack).
//   * Bricks of a segment are sorted by origin (z, y, x); each brick's mask marks the voxels it delivers.
//   * Storage is sparse: 8^3 bricks allocated when first touched, so memory follows the voxels inside the limit.
//   * Compute runs on TBB. With options.threads > 0 it runs in a task_arena of that size, otherwise in the
//     caller's arena. The result is bit-identical for any thread count.
//   * `interrupter` is polled inside every phase (band insertion, each propagation step's ranges, the second-ring
//     correction, emission and the consumer's chunks), so a stop request ends the call within ~10 ms of work on
//     each thread; the run then returns EngineResult::interrupted = true (bricks already delivered stay valid,
//     nothing more is delivered).
//   * With max_chunk_bricks = N > 0 a segment is handed over in chunks of at most N bricks, in (z, y, x) order,
//     the last one marked `complete` (it may be empty); the next chunk is built only after the callback returned,
//     so at most one chunk of output exists at a time and a callback that blocks pauses the engine. N = 0: one
//     callback per segment.
//   * Seeds are only read and must outlive the call; concurrent calls on the same or different seeds are fine.
//   * Memory: 8.6 bytes per touched voxel (2 more in paper mode), in whole bricks, plus one segment's (or chunk's)
//     output bricks (in the last segment the engine's bricks are freed while the output is built).
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/brick.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/seeds.h"
#include "core/stencil.h"

namespace distband {

enum class PropagationMode {
  /// The paper's method: vector propagation of the closest site, a voxel leaves the band when its lifespan
  /// ((1 + alpha) * t_min of its first distance + margin steps; see docs/algorithm.md) has run out.
  kPaper,
  /// Default: vector propagation until nothing changes (no lifespan cut-off), offers admitted in distance slices
  /// when there are many sites, plus (EngineOptions::second_ring) a correction at Voronoi boundaries that also
  /// tries the sites held within two voxels. Exact for point seeds.
  kExact,
};

std::string_view modeName(PropagationMode mode);
bool parseMode(std::string_view name, PropagationMode* mode);  ///< "paper", "exact"

struct EngineOptions {
  /// Unset: defaultStencil(seeds.kind).
  std::optional<StencilKind> stencil;
  PropagationMode mode = PropagationMode::kExact;
  double segment_length_world = 0;                                    ///< 0: a single segment
  double limit_world = std::numeric_limits<double>::infinity();        ///< distance limit (world units)
  int threads = 0;                                                     ///< 0: the caller's TBB arena
  /// Exact mode: run the second-ring correction at the end of each segment. Unset: on for point sites (it makes point
  /// and volume seeds exact), off for triangle sites (there it costs several times the propagation for ~0.01 voxel).
  std::optional<bool> second_ring;
  /// Paper mode only: lifespan = ceil(alpha * t_first) + margin steps. alpha < 0 uses the stencil's
  /// value; +infinity disables the lifespan (iterate until nothing changes). margin < 0 uses the default.
  double lifespan_alpha = -1;
  int lifespan_margin = -1;
  const Interrupter* interrupter = nullptr;  ///< polled in every phase; may be null
  size_t max_chunk_bricks = 0;               ///< > 0: hand segments over in chunks of at most this many bricks
  /// Also report each delivered voxel's closest feature (Brick::closest; what the ids mean: Seeds::FeatureKind).
  bool closest_features = false;
  /// Profiling only (bench/scaling_bench: how much parallel work each step holds): called on the run's thread before
  /// each propagation step with the number of work items it is about to push (front entries; the band's voxels for
  /// the first step of an exact band). Empty by default.
  std::function<void(int step, size_t items)> on_step;
};

struct SegmentStats {
  int index = 0;
  double lower_world = 0, upper_world = 0;
  int64_t voxels = 0;      ///< voxels delivered
  int64_t bricks = 0;      ///< brick messages delivered
  int steps = 0;           ///< propagation steps in this segment
  double seconds = 0;      ///< compute time of the segment (excluding the callback)
};

struct EngineResult {
  bool interrupted = false;
  int steps = 0;
  int64_t voxels = 0;          ///< voxels delivered
  int64_t updates = 0;         ///< accepted site updates (work measure)
  int64_t corrections = 0;     ///< voxels improved by the second-ring correction
  int64_t bricks_allocated = 0;
  double seconds = 0;
  /// After the run: freeing its state (bricks, fronts). Part of a stopped run's time to return, but not compute:
  /// it grows with the memory held (about 0.1 s a GiB on the 2-core development VM).
  double release_seconds = 0;
  std::vector<SegmentStats> segments;
};

/// Returns "" if the options are usable with this grid, otherwise a message naming the field and the rule.
std::string validateOptions(const Grid& grid, const EngineOptions& options);

using SegmentCallback = std::function<void(SegmentBricks&&)>;

/// Runs the engine. Preconditions (checked, std::invalid_argument): grid.validate() and validateOptions() are
/// empty, every band voxel lies inside the grid and names a site < seeds.siteCount() or kNoSite.
EngineResult computeDistanceField(const Grid& grid, const Seeds& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment);

/// The same, taking the seeds over (`seeds` is left empty): the band is freed as soon as it is in the engine, which
/// for a thin band around a large mesh is a sizeable part of the run's peak memory.
EngineResult computeDistanceField(const Grid& grid, Seeds&& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment);

/// The stencil of an EngineOptions without one: fcc12 for triangle sites (meshes in exact-feature mode: about half
/// cubic26's time at the same accuracy class, docs/benchmarks.md), cubic26 for point sites (points, volumes, and
/// meshes in paper mode, where it is the paper's stencil).
StencilKind defaultStencil(SiteKind kind);

/// The default lifespan margin (steps) added in paper mode; see docs/algorithm.md for how it was found.
int defaultLifespanMargin(StencilKind stencil);

}  // namespace distband
