// Point seeds: the distance to the nearest of a list of points (the paper's one-point and two-point cases).
// Contract: points are world coordinates and may lie outside the grid; each point seeds the voxels of the 3^3
// block around its nearest in-grid voxel. Unsigned. Returns kInvalidArgument (and leaves `out` untouched) for an
// empty list or non-finite coordinates.
// With `window` (a box of the grid) the seeds are for the engine grid grid.window(*window): the sites stay in the
// whole grid's unit space (Seeds::site_offset = window->min), so a tile's distances are bit-identical to the whole
// grid's, and a point outside the window seeds the block around its nearest window voxel.
#pragma once

#include <string>
#include <vector>

#include "core/grid.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

Status makePointSeeds(const Grid& grid, const std::vector<Vec3d>& world_points, Seeds* out,
                           const VoxelBox* window = nullptr);

}  // namespace distband
