#include "core/field/tiling.h"

#include <algorithm>
#include <cmath>

namespace distband {
namespace {

int bricksOf(int voxels) { return (voxels + kBrickSize - 1) / kBrickSize; }

}  // namespace

int tileHalo(double limit_voxels) {
  if (!std::isfinite(limit_voxels) || limit_voxels > kMaxGridDim) return -1;
  return int(std::ceil(std::max(0.0, limit_voxels))) + 2 * kBrickSize;
}

std::vector<TilePlan> planTiles(const Coord& dims, uint64_t max_tile_voxels, int halo_voxels) {
  const int grid_bricks[3] = {bricksOf(dims.x), bricksOf(dims.y), bricksOf(dims.z)};
  const int grid_dims[3] = {dims.x, dims.y, dims.z};
  int parts[3] = {1, 1, 1};
  auto tileBricks = [&](int a) { return (grid_bricks[a] + parts[a] - 1) / parts[a]; };
  auto tileExtent = [&](int a) { return std::min(grid_dims[a], tileBricks(a) * kBrickSize); };
  auto tileVoxels = [&] { return uint64_t(tileExtent(0)) * tileExtent(1) * tileExtent(2); };
  auto tileCount = [&] { return size_t(parts[0]) * parts[1] * parts[2]; };
  // Split the longest tile side (in voxels) until the tile fits; parts are chosen so tiles have whole bricks.
  while (tileVoxels() > std::max<uint64_t>(max_tile_voxels, kBrickVoxels)) {
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (tileBricks(a) > 1 && (axis < 0 || tileExtent(a) > tileExtent(axis))) axis = a;
    if (axis < 0) break;
    // The next part count that actually shrinks the tile along this axis.
    const int before = tileBricks(axis);
    int next = parts[axis] + 1;
    while ((grid_bricks[axis] + next - 1) / next == before) ++next;
    const int old = parts[axis];
    parts[axis] = next;
    if (tileCount() > kMaxTiles) {
      parts[axis] = old;
      break;
    }
  }
  const int step[3] = {tileBricks(0) * kBrickSize, tileBricks(1) * kBrickSize, tileBricks(2) * kBrickSize};
  std::vector<TilePlan> tiles;
  for (int z = 0; z < dims.z; z += step[2])
    for (int y = 0; y < dims.y; y += step[1])
      for (int x = 0; x < dims.x; x += step[0]) {
        TilePlan t;
        t.deliver.min = {x, y, z};
        t.deliver.dims = {std::min(step[0], dims.x - x), std::min(step[1], dims.y - y), std::min(step[2], dims.z - z)};
        if (halo_voxels < 0) {
          t.window = {{}, dims};
        } else {
          const int lo[3] = {x, y, z}, hi[3] = {x + t.deliver.dims.x, y + t.deliver.dims.y, z + t.deliver.dims.z};
          int wlo[3], whi[3];
          for (int a = 0; a < 3; ++a) {
            wlo[a] = std::max(0, (lo[a] - halo_voxels) / kBrickSize * kBrickSize);  // negative: 0
            whi[a] = std::min(grid_dims[a], bricksOf(hi[a] + halo_voxels) * kBrickSize);
          }
          t.window.min = {wlo[0], wlo[1], wlo[2]};
          t.window.dims = {whi[0] - wlo[0], whi[1] - wlo[1], whi[2] - wlo[2]};
        }
        tiles.push_back(t);
      }
  return tiles;
}

}  // namespace distband
