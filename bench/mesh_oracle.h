// Mesh oracle for the benches: the brute-force exact distance and winding number (tests/support/brute_mesh.h, no code
// shared with core) at sample voxels, judged by the documented bound (meshErrorBoundVoxels, bench/planned_field.h).
// Contract:
//   * sampleMesh(): brute force at `voxels` (in parallel): each one's exact distance and whether the winding number
//     puts it inside. checkMeshSamples() compares delivered `values` (world units, NaN: not delivered, counted as
//     missing) with them. A sign error is a voxel farther than 1e-3 voxel from the surface whose sign
//     disagrees with the exact winding number (> 0.5 inside); sign errors fail only where the caller says the sign is
//     defined (`closed`: a closed mesh with a signed field; an open mesh's inside is not defined where the winding
//     number is near 0.5, and the docs promise nothing there).
//   * The result's ok() is: max error <= bound, no sign error where `closed`, nothing missing where `require_all`.
//     describe() names the first bad voxel.
// Thread-safe; bench code only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bench/planned_field.h"
#include "core/grid.h"
#include "core/mesh/triangle_mesh.h"

namespace distband::bench {

struct MeshSampleCheck {
  double bound_voxels = 0;
  bool closed = true;  ///< sign errors fail (a closed mesh with a signed field)
  int64_t compared = 0, missing = 0, over_bound = 0, sign_errors = 0;
  double max_err_voxels = 0, mean_err_voxels = 0;
  Coord first_bad{-1, -1, -1};  ///< the first sample (in the order given) over the bound or with a sign error
  double first_bad_exact = 0;   ///< world units, signed by the winding number
  float first_bad_value = 0;

  bool ok(bool require_all = true) const {
    return over_bound == 0 && (!closed || sign_errors == 0) && (!require_all || missing == 0);
  }
  /// "max 0.0123 voxel (bound 0.15), 0 sign errors, 0 missing of 2000; first bad voxel (x, y, z): exact .., got .."
  std::string describe() const;
};

struct MeshSamples {
  std::vector<Coord> voxels;
  std::vector<double> distance;  ///< exact, unsigned, world units
  std::vector<uint8_t> inside;   ///< exact winding number > 0.5
};

MeshSamples sampleMesh(const TriangleMesh& mesh, const Grid& grid, std::vector<Coord> voxels);

/// `values[i]` is the delivered value at samples.voxels[i]; `closed`: whether sign errors fail.
MeshSampleCheck checkMeshSamples(const MeshSamples& samples, const std::vector<float>& values, double voxel_size,
                                 bool closed, double bound_voxels);

}  // namespace distband::bench
