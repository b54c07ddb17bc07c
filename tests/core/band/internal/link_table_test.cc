// Tests for core/engine/link_table: the links kept per position class and arrival direction (counts), that every
// link target is located right for every brick-local position, and that every dropped link is redundant: its
// target is the voxel the site came from, or one that voxel offered the same site to one step earlier.
#include "core/band/internal/link_table.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/brick.h"
#include "core/types.h"

namespace distband::band_internal {
namespace {

constexpr StencilKind kAll[] = {StencilKind::kCubic6, StencilKind::kCubic18, StencilKind::kCubic26,
                                StencilKind::kFcc12};

bool inStencil(const Stencil& s, const Coord& v) {
  return std::find(s.links.begin(), s.links.end(), v) != s.links.end();
}

size_t indexOf(const Stencil& s, const Coord& v) {
  return size_t(std::find(s.links.begin(), s.links.end(), v) - s.links.begin());
}

TEST(LinkTables, CountsPerArrivalDirection) {
  const Stencil& c6 = Stencil::get(StencilKind::kCubic6);
  const Stencil& c26 = Stencil::get(StencilKind::kCubic26);
  const LinkTables t6(c6, Vec3d{1, 1, 1}), t26(c26, Vec3d{1, 1, 1});
  const Coord interior{3, 4, 5};
  EXPECT_EQ(t6.linksFor(interior, kNoDirection).size(), 6u);
  EXPECT_EQ(t26.linksFor(interior, kNoDirection).size(), 26u);
  // cubic6, arrived along +x: only the way back (-x) is dropped.
  EXPECT_EQ(t6.linksFor(interior, uint32_t(indexOf(c6, {1, 0, 0}))).size(), 5u);
  // cubic26, arrived along +x: the sender reached every target with x <= 0 relative to here; 9 remain.
  EXPECT_EQ(t26.linksFor(interior, uint32_t(indexOf(c26, {1, 0, 0}))).size(), 9u);
  // cubic26, arrived along (1,1,1): the sender reached the targets in {-1,0}^3; 19 remain.
  EXPECT_EQ(t26.linksFor(interior, uint32_t(indexOf(c26, {1, 1, 1}))).size(), 19u);
  // The position in the brick changes where targets lie, not which are kept.
  for (uint32_t dir = 0; dir < c26.links.size(); ++dir)
    EXPECT_EQ(t26.linksFor({0, 7, 0}, dir).size(), t26.linksFor(interior, dir).size());
}

TEST(LinkTables, TargetsAreLocatedRightFromEveryPositionInTheBrick) {
  for (StencilKind kind : kAll) {
    const Stencil& s = Stencil::get(kind);
    const LinkTables t(s, Vec3d{1, 1, 1});
    for (int off = 0; off < kBrickVoxels; ++off) {
      const Coord l = brickLocal(off);
      for (uint32_t dir = 0; dir < 32; ++dir) {
        if (dir != kNoDirection && dir >= s.links.size()) continue;
        for (const Link& d : t.linksFor(l, dir)) {
          // Where the target really is: brick (-1..1 per axis) and local coordinate.
          const Coord g{l.x + d.x, l.y + d.y, l.z + d.z};
          auto brickOf = [](int v) { return v < 0 ? 0 : (v >= kBrickSize ? 2 : 1); };
          ASSERT_EQ(d.brick, brickOf(g.z) * 9 + brickOf(g.y) * 3 + brickOf(g.x));
          ASSERT_EQ(off + d.offset, brickOffset((g.x + 8) % 8, (g.y + 8) % 8, (g.z + 8) % 8));
          ASSERT_EQ(s.links[d.dir], (Coord{d.x, d.y, d.z}));
          ASSERT_EQ(d.propagates_to, !s.fcc);
        }
      }
    }
  }
}

TEST(LinkTables, EveryDroppedLinkIsRedundantAndEveryKeptOneIsNot) {
  for (StencilKind kind : kAll) {
    const Stencil& s = Stencil::get(kind);
    const LinkTables t(s, Vec3d{1, 1, 1});
    EXPECT_EQ(t.all().size(), s.links.size());
    for (uint32_t dir = 0; dir < s.links.size(); ++dir) {
      const Coord u = s.links[dir];
      const Coord src{4, 4, 4}, q{src.x - u.x, src.y - u.y, src.z - u.z};  // q sent the site along u
      const auto& kept = t.linksFor({4, 4, 4}, dir);
      for (const Coord& l : s.links) {
        const bool is_kept = std::any_of(kept.begin(), kept.end(),
                                         [&](const Link& d) { return d.x == l.x && d.y == l.y && d.z == l.z; });
        const Coord target{src.x + l.x, src.y + l.y, src.z + l.z};
        // Did q reach the target itself (it is q, or a stencil link away from q)?
        const Coord from_q{target.x - q.x, target.y - q.y, target.z - q.z};
        const bool q_reached = (from_q.x == 0 && from_q.y == 0 && from_q.z == 0) || inStencil(s, from_q);
        EXPECT_NE(is_kept, q_reached) << int(kind) << " dir " << dir << " link " << l.x << "," << l.y << "," << l.z;
      }
    }
  }
}

// A small vector propagation (one thread, point sites, Jacobi steps from a front of changed voxels as the engine
// runs them) with every link, and with the tables' links: dropping the links gives the same field.
std::vector<uint64_t> propagate(const Stencil& s, const LinkTables* tables, const std::vector<Vec3d>& sites, int n) {
  const LinkTables every(s, Vec3d{1, 1, 1});
  std::vector<uint64_t> key(size_t(n) * n * n, kUntouched);
  auto index = [n](const Coord& c) { return (size_t(c.z) * n + c.y) * n + c.x; };
  auto d2Of = [&](uint32_t site, const Coord& c) {
    const Vec3d p = sites[site];
    const double x = c.x - p.x, y = c.y - p.y, z = c.z - p.z;
    return float(x * x + y * y + z * z);
  };
  struct Entry {
    Coord c;
    uint32_t site, dir;
  };
  std::vector<Entry> front;
  for (uint32_t i = 0; i < sites.size(); ++i) {
    const Coord c{int(std::lround(sites[i].x)), int(std::lround(sites[i].y)), int(std::lround(sites[i].z))};
    const uint64_t k = packKey(d2Of(i, c), kNoDirection, i);
    if (k < key[index(c)]) key[index(c)] = k;
  }
  for (uint32_t i = 0; i < sites.size(); ++i) {
    const Coord c{int(std::lround(sites[i].x)), int(std::lround(sites[i].y)), int(std::lround(sites[i].z))};
    if (keySite(key[index(c)]) == i) front.push_back({c, i, kNoDirection});
  }
  while (!front.empty()) {
    std::vector<char> changed(key.size(), 0);
    std::vector<Coord> changed_list;
    for (const Entry& e : front) {
      const Coord local{e.c.x & 7, e.c.y & 7, e.c.z & 7};
      const std::vector<Link>& links = tables ? tables->linksFor(local, e.dir) : every.all();
      for (const Link& d : links) {
        const Coord g{e.c.x + d.x, e.c.y + d.y, e.c.z + d.z};
        if (g.x < 0 || g.y < 0 || g.z < 0 || g.x >= n || g.y >= n || g.z >= n) continue;
        const uint64_t k = packKey(d2Of(e.site, g), d.dir, e.site);
        if (k >= key[index(g)]) continue;
        key[index(g)] = k;
        if (s.propagates(g) && !changed[index(g)]) {
          changed[index(g)] = 1;
          changed_list.push_back(g);
        }
      }
    }
    front.clear();
    for (const Coord& c : changed_list) front.push_back({c, keySite(key[index(c)]), keyDir(key[index(c)])});
  }
  for (uint64_t& k : key) k &= ~uint64_t(31);  // the direction kept may differ; distance and site may not
  return key;
}

TEST(LinkTables, PropagationWithTheTablesMatchesPropagationWithEveryLink) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 19.0);
  std::vector<Vec3d> sites;
  for (int i = 0; i < 12; ++i) sites.push_back({u(rng), u(rng), u(rng)});
  for (StencilKind kind : kAll) {
    const Stencil& s = Stencil::get(kind);
    const LinkTables tables(s, Vec3d{1, 1, 1});
    const std::vector<uint64_t> full = propagate(s, nullptr, sites, 20), pruned = propagate(s, &tables, sites, 20);
    ASSERT_EQ(full.size(), pruned.size());
    size_t differ = 0;
    for (size_t i = 0; i < full.size(); ++i) differ += full[i] != pruned[i];
    EXPECT_EQ(differ, 0u) << "stencil " << int(kind);
  }
}

}  // namespace
}  // namespace distband::band_internal
