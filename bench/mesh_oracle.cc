#include "bench/mesh_oracle.h"

#include <cmath>

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "tests/support/brute_mesh.h"

namespace distband::bench {

std::string MeshSampleCheck::describe() const {
  std::string text = fmt::format("max error {:.4f} voxel (bound {:g}), {} over the bound, {} sign errors{}, {} missing "
                                 "of {}",
                                 max_err_voxels, bound_voxels, over_bound, sign_errors,
                                 closed ? "" : " (not checked: an open mesh or an unsigned field)", missing,
                                 compared + missing);
  if (first_bad.x >= 0)
    text += fmt::format("; first bad voxel ({}, {}, {}): exact {:.9g}, got {:.9g}", first_bad.x, first_bad.y,
                        first_bad.z, first_bad_exact, first_bad_value);
  return text;
}

MeshSamples sampleMesh(const TriangleMesh& mesh, const Grid& grid, std::vector<Coord> voxels) {
  MeshSamples m;
  m.voxels = std::move(voxels);
  const size_t n = m.voxels.size();
  m.distance.resize(n);
  m.inside.resize(n);
  tbb::parallel_for(size_t(0), n, [&](size_t i) {
    const Vec3d w = grid.worldOf(m.voxels[i]);
    m.distance[i] = testing::bruteDistance(mesh, w);
    m.inside[i] = testing::bruteWinding(mesh, w) > 0.5;
  });
  return m;
}

MeshSampleCheck checkMeshSamples(const MeshSamples& samples, const std::vector<float>& values, double h, bool closed,
                                 double bound_voxels) {
  const size_t n = samples.voxels.size();
  const std::vector<double>& distance = samples.distance;
  const std::vector<uint8_t>& inside = samples.inside;
  MeshSampleCheck c;
  c.bound_voxels = bound_voxels;
  c.closed = closed;
  double sum = 0;
  for (size_t i = 0; i < n; ++i) {
    if (std::isnan(values[i])) {
      ++c.missing;
      continue;
    }
    ++c.compared;
    const double err = std::abs(std::abs(double(values[i])) - distance[i]) / h;
    c.max_err_voxels = std::max(c.max_err_voxels, err);
    sum += err;
    const bool over = err > bound_voxels;
    const bool sign = distance[i] > 1e-3 * h && (values[i] < 0) != bool(inside[i]);
    c.over_bound += over;
    c.sign_errors += sign;
    if ((over || (sign && closed)) && c.first_bad.x < 0) {
      c.first_bad = samples.voxels[i];
      c.first_bad_exact = inside[i] ? -distance[i] : distance[i];
      c.first_bad_value = values[i];
    }
  }
  c.mean_err_voxels = c.compared ? sum / double(c.compared) : 0;
  return c;
}

}  // namespace distband::bench
