#include "core/seeds/point_seeds.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace distband {

std::string makePointSeeds(const Grid& grid, const std::vector<Vec3d>& world_points, Seeds* out) {
  if (world_points.empty()) return "point list is empty";
  Seeds seeds;
  seeds.kind = SiteKind::kPoint;
  const Coord dims = grid.dims();
  for (size_t i = 0; i < world_points.size(); ++i) {
    const Vec3d& w = world_points[i];
    if (!(std::isfinite(w.x) && std::isfinite(w.y) && std::isfinite(w.z)))
      return fmt::format("point {} has a non-finite coordinate", i);
    const Vec3d p = grid.indexOf(w);
    seeds.points.push_back(p);
    auto nearest = [](double v, int n) { return static_cast<int>(std::clamp(std::lround(v), 0L, long(n - 1))); };
    const Coord c{nearest(p.x, dims.x), nearest(p.y, dims.y), nearest(p.z, dims.z)};
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Coord v{c.x + dx, c.y + dy, c.z + dz};
          if (grid.contains(v)) seeds.band.push_back({v, static_cast<uint32_t>(i)});
        }
  }
  *out = std::move(seeds);
  return {};
}

}  // namespace distband
