// Tiling: a grid cut into brick-aligned tiles, for one query spread over several servers (server/tiled_query.h).
// Contract:
//   * planTiles() covers the grid with disjoint boxes of whole 8^3 bricks (a tile's far side may end at the grid's
//     face), each of at most max(max_tile_voxels, 512) voxels and as close to a cube as the brick grid allows; more
//     than kMaxTiles tiles are never made (the tiles then grow past max_tile_voxels). Ordered z, then y, then x.
//   * A tile's window is the tile grown by `halo_voxels` on every side, rounded out to whole bricks and clipped to
//     the grid (halo < 0: the whole grid). A window holds every seed that can reach the tile within the limit when
//     halo >= the limit in voxels; tileHalo() adds the margin that keeps band histories alike at tile borders.
// Pure functions of their arguments.
#pragma once

#include <cstdint>
#include <vector>

#include "core/grid.h"

namespace distband {

inline constexpr size_t kMaxTiles = 65536;

struct TilePlan {
  VoxelBox deliver;  ///< the voxels the tile delivers
  VoxelBox window;   ///< the voxels its server computes (deliver grown by the halo)
};

std::vector<TilePlan> planTiles(const Coord& dims, uint64_t max_tile_voxels, int halo_voxels);

/// The halo for a limit in voxels: the limit rounded up plus two bricks; -1 (the whole grid) without a finite limit.
int tileHalo(double limit_voxels);

}  // namespace distband
