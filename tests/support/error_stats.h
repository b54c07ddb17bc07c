// Test support: how far a computed field is from an oracle, in voxels.
// Contract: independent of core/ (plain std::vector in). `got_world` are the engine's float32 values in world
// units; `expected_vox` the oracle's exact distances in voxels (not squared). Each expected value is first
// rounded to float32 in world units (expected_vox * voxel_size), as the engine stores it, so a voxel the engine
// computed exactly has error 0. Only voxels with consider[i] != 0 are counted (all when `consider` is null).
// Thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace distband::oracle {

struct ErrorStats {
  int64_t count = 0;          ///< voxels compared
  int64_t off = 0;            ///< voxels with error > off_tolerance_vox
  double max_err_vox = 0;
  double mean_err_vox = 0;
  double frac_off = 0;        ///< off / count
  int64_t worst_index = -1;   ///< dense index of the voxel with the largest error
  double worst_expected_world = 0, worst_got_world = 0;
};

ErrorStats compareToOracle(const std::vector<float>& got_world, const std::vector<double>& expected_vox,
                           double voxel_size, const std::vector<uint8_t>* consider = nullptr,
                           double off_tolerance_vox = 1e-4);

/// "max 0.0123 mean 1.2e-06 off 3/262144 (1.1e-05) worst@(x,y,z) exp 12.34 got 12.35".
std::string formatErrorStats(const ErrorStats& s, int nx, int ny);

}  // namespace distband::oracle
