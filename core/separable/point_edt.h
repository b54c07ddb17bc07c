// Separable point EDT: the exact distance field of point seeds over the whole grid, computed axis by axis, for
// point sets that lie on few lattice planes (a handful of landmarks, sources, robot positions). Many scattered
// points take the band (core/band/band_engine.h); the planner (core/field/field_plan.h) chooses with separablePointsPay().
// Contract:
//   * Seeds: kPoint seeds (core/seeds/point_seeds.h); only `points`, `site_offset` and `site_feature` are read.
//     Every voxel of the grid is delivered with its distance to the nearest point, computed as the band engine
//     computes it — ((voxel + site_offset) * axis scale - point).lengthSqr() in double (unit space, core/grid.h), its
//     root times the voxel size, as float —
//     so both algorithms deliver the same values, and a tile's values equal the whole grid's.
//   * Method: points with equal z form a plane, points with equal (y, z) a line. Pass 1 finds, for each line and
//     each x, the line's nearest point; pass 2, for each plane and (x, y), the lower envelope over the plane's lines
//     of (y - line y)^2 + pass 1; pass 3, for each column (x, y), the envelope over the planes of
//     (z - plane z)^2 + pass 2. Each pass carries the winning point, whose distance is then computed as above.
//     Exact: squared Euclidean distance splits by axis, so these nested minima are the minimum over all points
//     (Felzenszwalb & Huttenlocher's argument with off-lattice apexes); a near-tie can only swap two points whose
//     distances agree to rounding.
//   * Cost: O(X * lines + X * Y * planes + X * Y * Z) time; memory 12 bytes per (plane, x, y) and 4 per voxel.
//   * No limit: options.limit_world must be +infinity (a limited point query is the band's, whose work follows it).
//   * Streaming, threads, interrupter: as computeSeparableVolumeField (core/separable/volume_edt.h): segments nearest first
//     after the whole field is known, chunks, bit-identical for any thread count, polled per task in every pass.
//     Closest features (options.closest_features): the point's index, or site_feature[index] when that is set.
//   * Points that are not finite in unit space (a huge world coordinate on a tiny voxel size) are infinitely far, as
//     in the band: they are nobody's nearest point unless every point is such, and then every distance is infinite.
// Errors (seed kind, no points, grid, a finite limit) throw std::invalid_argument.
#pragma once

#include <cstdint>
#include <vector>

#include "core/field/field_run.h"
#include "core/grid.h"
#include "core/seeds/seeds.h"

namespace distband {

/// How point seeds lie on the lattice's axes: what the separable point EDT's cost depends on.
struct PointLayout {
  int64_t points = 0;
  int64_t lines = 0;   ///< distinct (y, z)
  int64_t planes = 0;  ///< distinct z
};

/// The layout of `points` (any consistent coordinates: world, index or unit space).
PointLayout pointLayout(const std::vector<Vec3d>& points);

/// True when the separable point EDT's work beyond one pass over the grid (its per-line and per-plane passes) is at
/// most a quarter of a pass: lines + Y * planes <= Y * Z / 4 on `dims`. Its memory is then at most 7 bytes a voxel.
/// Measured (bench/edt_peer_bench, "two points"): there it costs a tenth of the band's time.
bool separablePointsPay(const Coord& dims, const PointLayout& layout);

FieldRunResult computeSeparablePointField(const Grid& grid, const Seeds& seeds, const FieldRunOptions& options,
                                        const SegmentCallback& on_segment);

}  // namespace distband
