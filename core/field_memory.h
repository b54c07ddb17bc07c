// Field memory: an upper estimate of the peak bytes one distance-field computation allocates, so a server can
// admit it against a byte budget before it allocates anything.
// Contract:
//   * estimateFieldMemory() is a pure function of counts known before any work: the grid, the touched-voxel bound
//     (core/band_extent.h), the seed sizes and the options. It is cheap (no allocation).
//   * The constants are measured, not guessed: bench/admission_bench runs each seed kind and mode in its own process
//     and compares the process's peak RSS growth with this estimate (docs/benchmarks.md has the table); the
//     estimate must stay above every measurement.
//   * What is counted: the engine's bricks (per touched voxel, whole bricks), its sparse brick table (per touched
//     super-block), front and deferred lists, the seeds (band list, site tables, sign data, Embree's BVH, dense region
//     labels of signed volumes), and one output chunk of bricks. Not counted: the caller's own buffers (a server adds its
//     stream buffer) and the input asset (already resident).
// Plain values; thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "core/engine.h"
#include "core/seeds/mesh_seeds.h"

namespace distband {

struct FieldMemoryInput {
  enum class SeedKind { kPoints, kVolume, kMesh };
  SeedKind seed_kind = SeedKind::kPoints;
  PropagationMode mode = PropagationMode::kExact;
  uint64_t grid_voxels = 0;
  uint64_t touched_voxels = 0;  ///< BandExtent::voxelBound()
  // Seed sizes (the ones of the seed kind matter).
  uint64_t points = 0;
  uint64_t volume_seed_voxels = 0, volume_boundary_voxels = 0;
  bool signed_volume = false;
  uint64_t mesh_vertices = 0, mesh_triangles = 0;
  double mesh_area_voxels = 0;  ///< the mesh's surface area in index space (voxel units squared)
  SignMethod mesh_sign = SignMethod::kPseudonormal;
  /// Bricks handed to the segment callback at once (EngineOptions::max_chunk_bricks); 0 = whole segments, which
  /// the estimate bounds by the touched voxels.
  uint64_t chunk_bricks = 0;
  bool closest_features = false;  ///< EngineOptions::closest_features: 4 KiB more per output brick
  /// FieldAlgorithm::kSeparable: no band state. Volumes: 4 bytes (8 signed) per grid voxel, or with a limit up to 8
  /// (16) per touched voxel. Points: 4 bytes per grid voxel and 12 per separable_plane_voxels.
  bool separable = false;
  bool limited = false;  ///< the query has a finite limit
  /// Separable point seeds (core/separable_points.h): planes x X x Y of the grid, the entries of its per-plane pass.
  uint64_t separable_plane_voxels = 0;
};

struct FieldMemoryEstimate {
  uint64_t engine_bytes = 0;  ///< bricks, brick table, fronts
  uint64_t seed_bytes = 0;    ///< band list, sites, sign data, BVH, region labels
  uint64_t output_bytes = 0;  ///< one chunk (or segment) of output bricks
  uint64_t total() const { return engine_bytes + seed_bytes + output_bytes; }
  std::string summary() const;  ///< "engine 1.2 GiB + seeds 40 MiB + output 8 MiB"
};

FieldMemoryEstimate estimateFieldMemory(const FieldMemoryInput& input);

/// Voxels in a mesh's initial band (within 1.5 voxels of the surface): ~3 per unit of area, plus the ends of the
/// band around every triangle, at most the touched voxels.
uint64_t meshBandVoxelEstimate(double area_voxels, uint64_t triangles, uint64_t touched_voxels);

}  // namespace distband
