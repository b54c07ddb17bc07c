#include "core/seeds/volume_seeds.h"

#include <memory>

#include <fmt/format.h>

namespace distband {

std::string makeVolumeSeeds(const Grid& grid, const std::vector<uint8_t>& mask, bool signed_distance, Seeds* out,
                            const Interrupter* interrupter) {
  if (static_cast<int64_t>(mask.size()) != grid.voxelCount())
    return fmt::format("mask has {} voxels, the grid {}", mask.size(), grid.voxelCount());
  const Coord d = grid.dims();
  const int64_t sy = d.x, sz = int64_t(d.x) * d.y;
  auto inside = [&](int64_t i) { return mask[i] != 0; };
  // A voxel is on its side's boundary when a 6-neighbour lies on the other side.
  auto onBoundary = [&](int x, int y, int z, int64_t i) {
    const bool in = inside(i);
    return (x > 0 && inside(i - 1) != in) || (x + 1 < d.x && inside(i + 1) != in) ||
           (y > 0 && inside(i - sy) != in) || (y + 1 < d.y && inside(i + sy) != in) ||
           (z > 0 && inside(i - sz) != in) || (z + 1 < d.z && inside(i + sz) != in);
  };
  Seeds seeds;
  seeds.kind = SiteKind::kPoint;
  int64_t n_inside = 0;
  // Site ids of boundary voxels, so a neighbour across the boundary can name it.
  std::vector<uint32_t> site_of;
  if (signed_distance) site_of.assign(mask.size(), kNoSite);
  for (int z = 0; z < d.z; ++z) {
    if (isInterrupted(interrupter)) return "interrupted";
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        const int64_t i = (int64_t(z) * d.y + y) * d.x + x;
        n_inside += inside(i);
        if (!signed_distance) {
          if (!inside(i)) continue;
          uint32_t site = kNoSite;
          if (onBoundary(x, y, z, i)) {
            site = static_cast<uint32_t>(seeds.points.size());
            seeds.points.push_back({double(x), double(y), double(z)});
          }
          seeds.band.push_back({{x, y, z}, site});
        } else if (onBoundary(x, y, z, i)) {
          site_of[i] = static_cast<uint32_t>(seeds.points.size());
          seeds.points.push_back({double(x), double(y), double(z)});
        }
      }
  }
  if (n_inside == 0) return "the seed mask has no nonzero voxel";
  if (signed_distance) {
    if (n_inside == grid.voxelCount()) return "the seed mask has no zero voxel, so a signed field is undefined";
    // Each boundary voxel starts with the nearest voxel across the boundary (a 6-neighbour, distance 1):
    // the lowest site id among them, so the choice does not depend on scan order.
    for (int z = 0; z < d.z; ++z) {
      if (isInterrupted(interrupter)) return "interrupted";
      for (int y = 0; y < d.y; ++y)
        for (int x = 0; x < d.x; ++x) {
          const int64_t i = (int64_t(z) * d.y + y) * d.x + x;
          if (site_of[i] == kNoSite) continue;
          const bool in = inside(i);
          uint32_t best = kNoSite;
          auto consider = [&](bool ok, int64_t j) {
            if (ok && inside(j) != in && site_of[j] < best) best = site_of[j];
          };
          consider(x > 0, i - 1);
          consider(x + 1 < d.x, i + 1);
          consider(y > 0, i - sy);
          consider(y + 1 < d.y, i + sy);
          consider(z > 0, i - sz);
          consider(z + 1 < d.z, i + sz);
          seeds.band.push_back({{x, y, z}, best});
        }
    }
    auto region = std::make_shared<std::vector<uint8_t>>(mask.size());
    for (size_t i = 0; i < mask.size(); ++i) {
      if (i % (size_t(1) << 22) == 0 && isInterrupted(interrupter)) return "interrupted";
      (*region)[i] = mask[i] != 0;
    }
    seeds.region = region;
    const Grid g = grid;
    seeds.sign = [region, g](Brick& brick, const uint32_t*) {
      for (int i = 0; i < kBrickVoxels; ++i) {
        if (!brick.mask.test(i)) continue;
        const Coord c = brick.origin + brickLocal(i);
        if ((*region)[g.denseIndex(c)]) brick.values[i] = -brick.values[i];
      }
    };
  }
  *out = std::move(seeds);
  return {};
}

}  // namespace distband
