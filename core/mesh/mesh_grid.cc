#include "core/mesh/mesh_grid.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace distband {

namespace {

// The padding that holds a band of the limit around bounds of longest extent `longest`: the smallest p >= the
// default with p * h >= limit, where h depends on p when the grid is sized by its resolution N
// (h = longest / (N - 1 - 2p)); then p >= L (N - 1) / (longest + 2L) in world units.
// Beyond the cap the band is clipped (gridForMesh reports it).
int paddingForLimit(const MeshGridOptions& o, const DistanceLimit& limit, double longest) {
  const bool in_voxels = limit.voxels > 0;
  if (!(in_voxels ? std::isfinite(limit.voxels) : std::isfinite(limit.world))) return kDefaultPaddingVoxels;
  double need = 0;  // voxels
  int cap = kMaxPaddingVoxels;
  if (o.resolution > 0) {
    cap = std::min(cap, std::max(0, (o.resolution - 1) / 4));  // the bounds keep at least half of the N voxels
    need = in_voxels ? limit.voxels
                     : (longest > 0 ? limit.world * (o.resolution - 1) / (longest + 2 * limit.world) : 0);
  } else {
    need = in_voxels ? limit.voxels : limit.world / o.voxel_size;
  }
  // The slack keeps an exact integer (limit 5 voxels -> 5) from rounding up.
  const double p = std::max<double>(kDefaultPaddingVoxels, std::ceil(need - 1e-9));
  return p > cap ? std::max(cap, kDefaultPaddingVoxels) : int(p);
}

}  // namespace

Status gridForMesh(const TriangleMesh& mesh, const MeshGridOptions& o, const DistanceLimit& limit, Grid* grid,
                   GridPadding* padding_out) {
  if ((o.voxel_size > 0) == (o.resolution > 0))
    return Status::InvalidArgument("give exactly one of voxel size (> 0) and resolution (> 0)");
  if (o.voxel_size > 0 && !std::isfinite(o.voxel_size)) return Status::InvalidArgument("voxel size must be finite");
  if (o.padding_voxels && (*o.padding_voxels < 0 || *o.padding_voxels > kMaxPaddingVoxels))
    return Status::InvalidArgument(fmt::format("padding must be in [0, {}] voxels (got {})", kMaxPaddingVoxels, *o.padding_voxels));
  if (o.box_min.has_value() != o.box_max.has_value()) return Status::InvalidArgument("an explicit box needs both its min and max corner");
  Vec3d lo, hi;
  if (o.box_min) {
    lo = *o.box_min, hi = *o.box_max;
    for (double v : {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z})
      if (!std::isfinite(v)) return Status::InvalidArgument("the box corners must be finite");
    if (!(hi.x >= lo.x && hi.y >= lo.y && hi.z >= lo.z)) return Status::InvalidArgument("the box max corner must be >= its min corner");
  } else {
    if (mesh.vertices.empty()) return Status::InvalidArgument("the mesh is empty");
    lo = hi = mesh.vertices[0];
    for (const Vec3d& v : mesh.vertices) {
      lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
      hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    }
  }
  const Vec3d ext = hi - lo;
  // Finite corners can still be farther apart than a double holds (-1e308 to 1e308): the sizes below would be NaN.
  if (!std::isfinite(ext.x) || !std::isfinite(ext.y) || !std::isfinite(ext.z))
    return Status::InvalidArgument(o.box_min ? "the box's corners are too far apart (its extent overflows)"
                                             : "the mesh's vertices are too far apart (its extent overflows)");
  const double longest = std::max({ext.x, ext.y, ext.z});
  if (o.resolution > kMaxGridDim) return Status::InvalidArgument(fmt::format("resolution must be <= {} (got {})", kMaxGridDim, o.resolution));
  GridPadding padding;
  if (o.padding_voxels) {
    padding.voxels = *o.padding_voxels;
  } else if (o.box_min) {
    padding.voxels = 0;
  } else {
    padding.voxels = paddingForLimit(o, limit, longest);
  }
  double h = o.voxel_size;
  if (o.resolution > 0) {
    const int span = o.resolution - 1 - 2 * padding.voxels;
    if (span < 1)
      return Status::InvalidArgument(fmt::format("resolution {} leaves no voxel inside a padding of {} on both sides", o.resolution,
                         padding.voxels));
    if (!(longest > 0)) return Status::InvalidArgument("the box has zero extent, so a resolution cannot size it (give a voxel size)");
    h = longest / span;
    if (!(h > 0))  // a subnormal extent: the voxel size underflows to 0
      return Status::InvalidArgument(
          fmt::format("the bounds' extent {:g} is too small to be split into {} voxels", longest, span));
  }
  if (!o.box_min) {
    const double limit_voxels = limit.voxels > 0 ? limit.voxels : limit.world / h;
    padding.band_clipped = std::isfinite(limit_voxels) && padding.voxels < limit_voxels - 1e-9;
  }
  const double pad = padding.voxels;
  auto count = [&](double e) {
    // Voxels covering [lo, lo + e] plus padding; the small slack keeps N exact when e / h is an integer.
    const double cells = std::ceil(e / h - 1e-9);
    return cells + 1 + 2 * pad;
  };
  const double nx = count(ext.x), ny = count(ext.y), nz = count(ext.z);
  // Written so that a NaN fails it too, should one get past the checks above.
  if (!(nx <= kMaxGridDim && ny <= kMaxGridDim && nz <= kMaxGridDim))
    return Status::InvalidArgument(fmt::format(
        "the grid would be {:.0f}x{:.0f}x{:.0f} voxels; at most {} per axis are allowed", nx, ny, nz, kMaxGridDim));
  Grid g(lo - Vec3d{pad * h, pad * h, pad * h}, h, {int(nx), int(ny), int(nz)});
  if (Status s = g.validate(); !s.ok()) return s;
  *grid = g;
  if (padding_out) *padding_out = padding;
  return Status::Ok();
}

}  // namespace distband
