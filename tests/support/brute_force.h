// Test oracle: brute-force Euclidean distance from every voxel centre to the nearest of a set of points.
// Contract: independent of core/ by design (no distband header is included, plain std::vector in and out), so
// it cannot share a bug with the engine. Index space: voxel (x, y, z) is the point (x, y, z); the result is
// x-fastest (index (z*ny + y)*nx + x) and holds SQUARED distances in voxel units, computed in double.
// O(voxels * points); meant for test-sized grids. Thread-safe.
#pragma once

#include <array>
#include <vector>

namespace distband::oracle {

std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points);

}  // namespace distband::oracle
