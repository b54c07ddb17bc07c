#include "core/seeds/point_seeds.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace distband {

Status makePointSeeds(const Grid& grid, const std::vector<Vec3d>& world_points, Seeds* out,
                           const VoxelBox* window) {
  if (world_points.empty()) return Status::InvalidArgument("point list is empty");
  Seeds seeds;
  seeds.kind = SiteKind::kPoint;
  const VoxelBox box = window ? *window : grid.box();
  seeds.site_offset = box.min;
  const Grid engine_grid = window ? grid.window(box) : grid;
  const Coord dims = box.dims;
  for (size_t i = 0; i < world_points.size(); ++i) {
    const Vec3d& w = world_points[i];
    if (!(std::isfinite(w.x) && std::isfinite(w.y) && std::isfinite(w.z)))
      return Status::InvalidArgument(fmt::format("point {} has a non-finite coordinate", i));
    const Vec3d p = grid.unitsOf(w);  // the site, in unit space
    seeds.points.push_back(p);
    const Vec3d& r = grid.axisScale();
    auto nearest = [](double v, int lo, int n) {
      return static_cast<int>(std::clamp(std::lround(std::clamp(v, -1e9, 1e9)) - lo, 0L, long(n - 1)));
    };
    const Coord c{nearest(p.x / r.x, box.min.x, dims.x), nearest(p.y / r.y, box.min.y, dims.y),
                  nearest(p.z / r.z, box.min.z, dims.z)};
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Coord v{c.x + dx, c.y + dy, c.z + dz};
          if (engine_grid.contains(v)) seeds.band.push_back({v, static_cast<uint32_t>(i)});
        }
  }
  *out = std::move(seeds);
  return Status::Ok();
}

}  // namespace distband
