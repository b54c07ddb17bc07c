#include "core/field/field_memory.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/seeds/mesh_seeds.h"
#include "core/seeds/mesh_sign.h"

namespace distband {
namespace {

// Measured constants (bench/admission_bench; docs/benchmarks.md "Admission estimates"). Bytes unless noted.
constexpr double kEngineBytesPerVoxel = 9.0;        // key (8) + 5 bit sets, in whole bricks (exact mode)
constexpr double kLifespanBytesPerVoxel = 2.0;      // paper mode's expiry steps
constexpr double kFrontBytesPerVoxel = 3.0;         // front, next front and deferred offers (12 B entries)
// The sparse brick table (core/band/internal/brick_table.h): 24 bytes of top level and directory per super-block of the grid
// (16^3 bricks), and 32 KiB of slots plus a page per touched super-block. Touched super-blocks are bounded by one per
// 8 touched bricks (a band is compact: thin shells included), 8 per point seed (a ball at a super-block corner) and 64.
constexpr double kSuperBlockBricks = 4096;
constexpr double kTopBytesPerSuperBlock = 24;
constexpr double kBytesPerTouchedSuperBlock = 36 << 10;
constexpr double kOutputBytesPerBrick = sizeof(Brick) + 64;
constexpr double kPointSeedBytes = 24 + 27 * 16;    // the point and its 3^3 block of band voxels
constexpr double kVolumeSeedBytesPerSeedVoxel = 16;      // unsigned: every seed voxel is a band voxel
constexpr double kVolumeSeedBytesPerBoundaryVoxel = 40;  // site (24) + band voxel (16)
constexpr double kSignedVolumeBytesPerGridVoxel = 5;     // region labels (1) + the scan's site ids (4)
constexpr double kMeshBytesPerTriangle = 400;   // index-space triangles, normals, pseudonormals, BVH / winding tree
constexpr double kMeshBytesPerBandVoxel = 80;   // scan candidates, band list, paper-mode site points
constexpr double kMeshBandVoxelsPerArea = 3.5;      // 2 x 1.5 voxels, plus lattice effects
constexpr double kMeshBandVoxelsPerTriangle = 8;    // the band's rounded ends, counted per triangle
constexpr double kSeparableBandBytesPerVoxel = 8;    // squared distances (4) in slabs used at least half
constexpr double kSeparableBytesPerBandBrick = 96;  // pool pointer, run lists, segment ranges, output order
constexpr double kSafety = 1.15;                // allocator slack on top of the measured sizes
constexpr uint64_t kFixedBytes = uint64_t(8) << 20;  // per-run constants (thread buffers, arena)

}  // namespace

std::string FieldMemoryEstimate::summary() const {
  auto mib = [](uint64_t b) { return b / 1048576.0; };
  return fmt::format("engine {:.1f} MiB + seeds {:.1f} MiB + output {:.1f} MiB", mib(engine_bytes), mib(seed_bytes),
                     mib(output_bytes));
}

uint64_t meshBandVoxelEstimate(double area_voxels, uint64_t triangles, uint64_t touched_voxels) {
  const double band = kMeshBandVoxelsPerArea * area_voxels + kMeshBandVoxelsPerTriangle * double(triangles);
  return uint64_t(std::min(band, double(touched_voxels)));
}

FieldMemoryEstimate estimateFieldMemory(const FieldPlan& plan, const Grid& grid, const SeedCounts& in,
                                        uint64_t touched_voxels, uint64_t chunk_bricks) {
  const uint64_t grid_voxels = uint64_t(grid.voxelCount());
  const bool separable = plan.algorithm == FieldAlgorithm::kSeparable;
  const bool limited = std::isfinite(plan.limit_world);
  const bool signed_volume = plan.seeds == SeedKind::kVolume && plan.inside_negative;
  const uint64_t separable_plane_voxels =
      plan.point_layout ? uint64_t(plan.point_layout->planes) * grid.dims().x * grid.dims().y : 0;
  const double touched = double(std::min(touched_voxels, grid_voxels));
  const double touched_bricks = touched / kBrickVoxels;
  FieldMemoryEstimate e;
  const double grid_super_blocks = std::ceil(double(grid_voxels) / kBrickVoxels / kSuperBlockBricks);
  const double touched_super_blocks =
      std::min(grid_super_blocks, touched_bricks / 8 + 8 * double(in.points) + 64);
  double engine = touched * (kEngineBytesPerVoxel + kFrontBytesPerVoxel) + grid_super_blocks * kTopBytesPerSuperBlock +
                  touched_super_blocks * kBytesPerTouchedSuperBlock;
  if (plan.mode == PropagationMode::kPaper) engine += touched * kLifespanBytesPerVoxel;
  double seeds = 0;
  switch (plan.seeds) {
    case SeedKind::kPoints: seeds = double(in.points) * kPointSeedBytes; break;
    case SeedKind::kVolume:
      if (signed_volume)
        seeds = double(grid_voxels) * kSignedVolumeBytesPerGridVoxel +
                double(in.volume_boundary_voxels) * kVolumeSeedBytesPerBoundaryVoxel;
      else
        seeds = double(in.volume_seed_voxels) * kVolumeSeedBytesPerSeedVoxel +
                double(in.volume_boundary_voxels) * kVolumeSeedBytesPerBoundaryVoxel;
      break;
    case SeedKind::kMesh: {
      const double band = double(meshBandVoxelEstimate(in.mesh_area_voxels, in.mesh_triangles, touched_voxels));
      seeds = double(in.mesh_triangles) * kMeshBytesPerTriangle + band * kMeshBytesPerBandVoxel;
      // What the constants do not cover, for long thin triangles: the scan's (brick, triangle) pairs, and the winding
      // sign's boundary pieces (at most its budget).
      seeds += double(in.mesh_scan_pairs) * kMeshScanPairBytes;
      if (plan.mesh_sign == SignMethod::kWinding) seeds += double(MeshSign::maxBoundaryPieceBytes(in.mesh_triangles));
      break;
    }
  }
  if (separable) {  // no band state, and no seeds but a point list
    // The outside's cells (4 bytes a voxel; 8 with the nearest seed's label), and a signed field's inside's (4).
    const double sides = (plan.nearest_label ? 2 : 1) + (signed_volume ? 1 : 0);
    if (limited)
      // Within a limit: 4 bytes per voxel of the bricks that hold a value (inside the touched bound: the boundary's
      // bricks grown by the limit), up to twice that in partly used slabs (core/separable/internal/limited_band.h),
      // their run lists, and five bytes per grid brick for the volume's classification.
      engine = touched * kSeparableBandBytesPerVoxel * sides + touched_bricks * kSeparableBytesPerBandBrick +
               5 * double(grid_voxels) / kBrickVoxels;
    else if (plan.seeds == SeedKind::kPoints)
      // Points: a nearest-point index per grid voxel, pass 2's squared distance and point per plane entry, segment
      // lists per brick; the sorted points.
      engine = double(grid_voxels) * 4 + double(separable_plane_voxels) * 12 +
               double(grid_voxels) / kBrickVoxels * 24 + double(in.points) * 16;
    else  // whole grid: squared distances per grid voxel, segment lists per brick
      engine = double(grid_voxels) * 4 * sides + double(grid_voxels) / kBrickVoxels * 24;
    if (plan.seeds != SeedKind::kPoints) seeds = 0;
  }
  const double chunk = chunk_bricks ? std::min(double(chunk_bricks), touched_bricks) : touched_bricks;
  e.engine_bytes = uint64_t(engine * kSafety) + kFixedBytes;
  e.seed_bytes = uint64_t(seeds * kSafety);
  const double closest_bytes = plan.hasClosestFeatures() ? kBrickVoxels * sizeof(int64_t) : 0;
  e.output_bytes = uint64_t((chunk + 1) * (kOutputBytesPerBrick + closest_bytes) * kSafety);
  return e;
}

}  // namespace distband
