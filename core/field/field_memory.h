// Field memory: an upper estimate of the peak bytes one distance-field computation allocates, so a server can
// admit it against a byte budget before it allocates anything.
// Contract:
//   * estimateFieldMemory() is a pure function of what is known before any work: the plan, the grid, the
//     touched-voxel bound (core/field/band_extent.h) and the seed sizes. It is cheap (no allocation).
//   * The constants are measured, not guessed: bench/admission_bench runs each seed kind and mode in its own process
//     and compares the process's peak RSS growth with this estimate (docs/benchmarks.md has the table); the
//     estimate must stay above every measurement.
//   * What is counted: the engine's bricks (per touched voxel, whole bricks), its sparse brick table (per touched
//     super-block), front and deferred lists, the seeds (band list, site tables, sign data, Embree's BVH, a mesh scan's
//     (brick, triangle) pairs and the winding sign's boundary pieces, which grow with long thin triangles, dense region
//     labels of signed volumes), and one output chunk of bricks. Not counted: the caller's own buffers (a server adds its
//     stream buffer) and the input asset (already resident).
// Plain values; thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "core/field/field_plan.h"
#include "core/grid.h"

namespace distband {

/// The seeds' sizes, known before any work (an asset's counts, a request's point list).
struct SeedCounts {
  uint64_t points = 0;
  uint64_t volume_seed_voxels = 0, volume_boundary_voxels = 0;
  uint64_t mesh_vertices = 0, mesh_triangles = 0;
  double mesh_area_voxels = 0;  ///< the mesh's surface area in index space (voxel units squared)
  uint64_t mesh_scan_pairs = 0;  ///< the seed scan's (brick, triangle) pairs (core/seeds/mesh_seeds.h: meshScanPairs)
};

struct FieldMemoryEstimate {
  uint64_t engine_bytes = 0;  ///< bricks, brick table, fronts
  uint64_t seed_bytes = 0;    ///< band list, sites, sign data, BVH, region labels
  uint64_t output_bytes = 0;  ///< one chunk (or segment) of output bricks
  uint64_t total() const { return engine_bytes + seed_bytes + output_bytes; }
  std::string summary() const;  ///< "engine 1.2 GiB + seeds 40 MiB + output 8 MiB"
};

/// The estimate for a run of `plan` on `grid` (the grid the algorithm runs on: a tile's window for a tile).
/// `touched_voxels`: BandExtent::voxelBound() of the seeds within the limit. `chunk_bricks`: bricks handed to the
/// segment callback at once (FieldRunOptions::max_chunk_bricks; 0 = whole segments, bounded by the touched voxels).
/// What the plan decides matters: the algorithm (the separable EDTs hold no band state: volumes 4 bytes a grid voxel,
/// 4 more signed and 4 more with nearest labels, or with a limit up to twice that a touched voxel; points 4 bytes a grid voxel and 12 per (plane, x, y) of
/// plan.point_layout), the mode (paper mode's lifespans), the seeds and their sign, closest features (4 KiB more per
/// output brick).
FieldMemoryEstimate estimateFieldMemory(const FieldPlan& plan, const Grid& grid, const SeedCounts& seeds,
                                        uint64_t touched_voxels, uint64_t chunk_bricks);

/// Voxels in a mesh's initial band (within 1.5 voxels of the surface): ~3 per unit of area, plus the ends of the
/// band around every triangle, at most the touched voxels.
uint64_t meshBandVoxelEstimate(double area_voxels, uint64_t triangles, uint64_t touched_voxels);

}  // namespace distband
