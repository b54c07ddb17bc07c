#include "core/band/internal/link_table.h"

#include <algorithm>

#include "core/brick.h"

namespace distband::band_internal {

LinkTables::LinkTables(const Stencil& stencil, const Vec3d& scale) {
  const std::vector<Coord>& sl = stencil.links;
  auto isLinkOrZero = [&](const Coord& v) {
    if (v.x == 0 && v.y == 0 && v.z == 0) return true;
    return std::find(sl.begin(), sl.end(), v) != sl.end();
  };
  for (size_t i = 0; i < sl.size(); ++i) {
    const Coord& l = sl[i];
    links_.push_back({l.x, l.y, l.z, l.x * 64 + l.y * 8 + l.z, 13, uint32_t(i), l.x * scale.x, l.y * scale.y, l.z * scale.z,
                      !stencil.fcc});
  }
  const int rep_local[3] = {0, 1, kBrickSize - 1};  // a representative local coordinate of each class
  for (int c = 0; c < 27; ++c) {
    const Coord src{rep_local[c % 3], rep_local[(c / 3) % 3], rep_local[c / 9]};
    for (uint32_t dir = 0; dir < 32; ++dir) {
      if (dir != kNoDirection && dir >= sl.size()) continue;
      for (Link link : links_) {
        // The source received its site along link `dir` from Q = source - sl[dir], which offered the same site
        // to all of its own links one step earlier: a target that is one of them (or Q) gains nothing.
        if (dir != kNoDirection) {
          const Coord& u = sl[dir];
          if (isLinkOrZero({link.x + u.x, link.y + u.y, link.z + u.z})) continue;
        }
        const int lx = src.x + link.x, ly = src.y + link.y, lz = src.z + link.z;
        const int sx = lx >> kBrickLog2, sy = ly >> kBrickLog2, sz = lz >> kBrickLog2;
        link.brick = (sz + 1) * 9 + (sy + 1) * 3 + (sx + 1);
        link.offset = brickOffset(lx & 7, ly & 7, lz & 7) - brickOffset(src.x, src.y, src.z);
        tables_[c * 32 + dir].push_back(link);
        if (link.brick != 13) bricks_[c * 32 + dir] |= 1u << link.brick;
      }
    }
  }
}

}  // namespace distband::band_internal
