#include "core/mesh/mesh_grid.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace distband {

std::string gridForMesh(const TriangleMesh& mesh, const MeshGridOptions& o, Grid* grid) {
  if ((o.voxel_size > 0) == (o.resolution > 0))
    return "give exactly one of voxel size (> 0) and resolution (> 0)";
  if (o.voxel_size > 0 && !std::isfinite(o.voxel_size)) return "voxel size must be finite";
  if (o.padding_voxels < 0 || o.padding_voxels > kMaxGridDim / 4)
    return fmt::format("padding must be in [0, {}] voxels (got {})", kMaxGridDim / 4, o.padding_voxels);
  if (o.box_min.has_value() != o.box_max.has_value()) return "an explicit box needs both its min and max corner";
  Vec3d lo, hi;
  if (o.box_min) {
    lo = *o.box_min, hi = *o.box_max;
    for (double v : {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z})
      if (!std::isfinite(v)) return "the box corners must be finite";
    if (!(hi.x >= lo.x && hi.y >= lo.y && hi.z >= lo.z)) return "the box max corner must be >= its min corner";
  } else {
    if (mesh.vertices.empty()) return "the mesh is empty";
    lo = hi = mesh.vertices[0];
    for (const Vec3d& v : mesh.vertices) {
      lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
      hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    }
  }
  const Vec3d ext = hi - lo;
  const double longest = std::max({ext.x, ext.y, ext.z});
  double h = o.voxel_size;
  if (o.resolution > 0) {
    const int span = o.resolution - 1 - 2 * o.padding_voxels;
    if (o.resolution > kMaxGridDim)
      return fmt::format("resolution must be <= {} (got {})", kMaxGridDim, o.resolution);
    if (span < 1)
      return fmt::format("resolution {} leaves no voxel inside a padding of {} on both sides", o.resolution,
                         o.padding_voxels);
    if (!(longest > 0)) return "the box has zero extent, so a resolution cannot size it (give a voxel size)";
    h = longest / span;
  }
  const double pad = o.padding_voxels;
  auto count = [&](double e) {
    // Voxels covering [lo, lo + e] plus padding; the small slack keeps N exact when e / h is an integer.
    const double cells = std::ceil(e / h - 1e-9);
    return cells + 1 + 2 * pad;
  };
  const double nx = count(ext.x), ny = count(ext.y), nz = count(ext.z);
  if (std::max({nx, ny, nz}) > kMaxGridDim)
    return fmt::format("the grid would be {:.0f}x{:.0f}x{:.0f} voxels; at most {} per axis are allowed", nx, ny, nz,
                       kMaxGridDim);
  Grid g(lo - Vec3d{pad * h, pad * h, pad * h}, h, {int(nx), int(ny), int(nz)});
  if (std::string e = g.validate(); !e.empty()) return e;
  *grid = g;
  return {};
}

}  // namespace distband
