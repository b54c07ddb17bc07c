// Test oracle: brute-force Euclidean distance from every voxel centre to the nearest of a set of points.
// Contract: independent of core/ by design (no distband header is included, plain std::vector in and out), so
// it cannot share a bug with the engine. Index space: voxel (x, y, z) is the point (x, y, z); the result is
// x-fastest (index (z*ny + y)*nx + x) and holds SQUARED distances in voxel units, computed in double.
// O(voxels * points); meant for test-sized grids. Thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace distband::oracle {

std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points);

/// The same with voxels of `spacing` (x, y, z): voxel (x, y, z) and point p (index space) are at spacing * (x, y, z)
/// and spacing * p; SQUARED distances in those (world) units.
std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points,
                                          const std::array<double, 3>& spacing);

/// Label volumes (x fastest, 0 = background), by brute force over every pair of voxels:
///   otherLabelDistance: for a voxel of label L != 0, the distance (world units, spacing as above) to the nearest voxel
///     whose label differs from L — with `black_border` the voxels just outside the grid count as label 0 —, +infinity
///     when there is none; 0 for label 0 (seung-lab edt's edt::edt).
///   nearestSeedLabel: for every voxel, the label of the nearest voxel of label != 0 (itself for such a voxel), and
///     whether that nearest voxel is unique (its distance beats every other seed's by more than rounding).
std::vector<double> otherLabelDistance(int nx, int ny, int nz, const std::vector<uint32_t>& labels,
                                       const std::array<double, 3>& spacing, bool black_border);
void nearestSeedLabel(int nx, int ny, int nz, const std::vector<uint32_t>& labels,
                      const std::array<double, 3>& spacing, std::vector<uint32_t>* label, std::vector<bool>* unique);

}  // namespace distband::oracle
