// Test oracle: the exact Euclidean distance transform of a 3-D mask (Felzenszwalb & Huttenlocher 2012,
// "Distance Transforms of Sampled Functions": three separable passes of the 1-D lower envelope of parabolas).
// Contract: independent of core/ by design (no distband header is included, plain std::vector in and out).
// Masks and results are x-fastest (index (z*ny + y)*nx + x), voxel pitch 1.
//   edtSqr(mask)     : SQUARED distance from each voxel centre to the nearest nonzero voxel centre (0 on the
//                      mask; +infinity everywhere if the mask is empty) — scipy's distance_transform_edt(mask==0)^2.
//   signedEdt(mask)  : edt(mask == 0) - edt(mask != 0) in voxels (not squared): positive outside (distance to the
//                      nearest mask voxel), negative inside (minus the distance to the nearest non-mask voxel).
// Exact: squared distances are integers, represented exactly in double. Thread-safe.
#pragma once

#include <cstdint>
#include <vector>

namespace distband::oracle {

std::vector<double> edtSqr(int nx, int ny, int nz, const std::vector<uint8_t>& mask);

std::vector<double> signedEdt(int nx, int ny, int nz, const std::vector<uint8_t>& mask);

/// The same with voxels of `spacing` (x, y, z) world units: distances in world units (scipy's `sampling`), squared
/// for edtSqr. Exact up to double rounding.
std::vector<double> edtSqr(int nx, int ny, int nz, const std::vector<uint8_t>& mask, const double spacing[3]);
std::vector<double> signedEdt(int nx, int ny, int nz, const std::vector<uint8_t>& mask, const double spacing[3]);

}  // namespace distband::oracle
