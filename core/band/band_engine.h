// Band engine: the adaptive iteration on an evolving active band (SMI 2009), segment by segment — the algorithm for
// meshes and scattered points, and for any seeds when a stencil, paper mode or closest features are asked for.
// Contract: computeBandField(grid, seeds, options, on_segment) propagates closest sites from seeds.band over the
// grid and streams every finished segment under the run contract of core/field/field_run.h (segments nearest
// first, sorted bricks, chunks, threads, interruption), with these band specifics:
//   * Rarely a voxel is first reached only in a later segment, with a value below that segment's lower bound: it is
//     delivered there. The engine computes at most one voxel beyond the limit (the admission slack).
//   * Storage is sparse: 8^3 bricks allocated when first touched, so memory follows the voxels inside the limit:
//     8.6 bytes per touched voxel (2 more in paper mode), in whole bricks, plus one segment's (or chunk's) output
//     bricks (in the last segment the engine's bricks are freed while the output is built).
//   * The interrupter is polled in band insertion, each propagation step's ranges, the second-ring correction,
//     emission and the consumer's chunks.
//   * Seeds are only read and must outlive the call; concurrent calls on the same or different seeds are fine.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/brick.h"
#include "core/field/field_run.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/seeds/seeds.h"
#include "core/status.h"
#include "core/stencil.h"

namespace distband {

enum class PropagationMode {
  /// The paper's method: vector propagation of the closest site, a voxel leaves the band when its lifespan
  /// ((1 + alpha) * t_min of its first distance + margin steps; see docs/algorithm.md) has run out.
  kPaper,
  /// Default: vector propagation until nothing changes (no lifespan cut-off), offers admitted in distance slices
  /// when there are many sites, plus (BandOptions::second_ring) a correction at Voronoi boundaries that also
  /// tries the sites held within two voxels. Exact for point seeds.
  kExact,
};

/// Every mode, the default first.
inline constexpr PropagationMode kPropagationModes[] = {PropagationMode::kExact, PropagationMode::kPaper};
std::string_view modeName(PropagationMode mode);
bool parseMode(std::string_view name, PropagationMode* mode);  ///< "paper", "exact"

/// The band's options: the run's (core/field/field_run.h) and the settings only propagation has.
struct BandOptions : FieldRunOptions {
  /// Unset: defaultStencil(seeds.kind, grid.cubic()).
  std::optional<StencilKind> stencil;
  PropagationMode mode = PropagationMode::kExact;
  /// Exact mode: run the second-ring correction at the end of each segment. Unset: on for point sites (it makes point
  /// and volume seeds exact), off for triangle sites (there it costs several times the propagation for ~0.01 voxel).
  std::optional<bool> second_ring;
  /// Paper mode only: lifespan = ceil(alpha * t_first) + margin steps. alpha < 0 uses the stencil's
  /// value; +infinity disables the lifespan (iterate until nothing changes). margin < 0 uses the default.
  double lifespan_alpha = -1;
  int lifespan_margin = -1;
  /// Profiling only (bench/scaling_bench: how much parallel work each step holds): called on the run's thread before
  /// each propagation step with the number of work items it is about to push (front entries; the band's voxels for
  /// the first step of an exact band). Empty by default.
  std::function<void(int step, size_t items)> on_step;
};

/// validateRunOptions (core/field/field_run.h) and the band's own rules: OK, or kInvalidArgument naming the field.
Status validateBandOptions(const Grid& grid, const BandOptions& options);

/// Runs the engine. Preconditions (checked, std::invalid_argument): grid.validate() and validateBandOptions() are
/// empty, every band voxel lies inside the grid and names a site < seeds.siteCount() or kNoSite.
FieldRunResult computeBandField(const Grid& grid, const Seeds& seeds, const BandOptions& options,
                                  const SegmentCallback& on_segment);

/// The same, taking the seeds over (`seeds` is left empty): the band is freed as soon as it is in the engine, which
/// for a thin band around a large mesh is a sizeable part of the run's peak memory.
FieldRunResult computeBandField(const Grid& grid, Seeds&& seeds, const BandOptions& options,
                                  const SegmentCallback& on_segment);

/// The stencil of BandOptions without one: fcc12 for triangle sites on a cubic grid (meshes in exact-feature mode:
/// about half cubic26's time at the same accuracy class, docs/benchmarks.md), cubic26 for point sites (points,
/// volumes, and meshes in paper mode, where it is the paper's stencil) and on anisotropic grids (fcc12 fills its odd
/// half from axial neighbours, which there lie at different distances: measured up to 0.6 voxel off on a sphere with
/// spacing 1 x 2 x 3, cubic26 within 0.03 beyond the tessellation).
StencilKind defaultStencil(SiteKind kind, bool cubic_grid = true);

/// The default lifespan margin (steps) added in paper mode; see docs/algorithm.md for how it was found.
int defaultLifespanMargin(StencilKind stencil);

}  // namespace distband
