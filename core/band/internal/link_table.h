// LinkTables: a stencil's links, precomputed for the propagation's inner loop.
// Contract: linksFor(local, dir) lists the links a voxel at brick-local coordinate `local` must offer along when it
// received its site along link `dir` (kNoDirection: from the band, a correction or a replay, so all links). Each
// Link carries where its target lies relative to the source's brick (which of the 3x3x3 neighbouring bricks, and the
// offset within it). Links whose target the previous offerer already reached with the same site are dropped.
// Built once per run (BandState), then only read: safe to share between threads.
#pragma once

#include <cstdint>
#include <vector>

#include "core/band/internal/band_key.h"
#include "core/grid.h"
#include "core/stencil.h"

namespace distband::band_internal {

struct Link {
  int x, y, z;
  int offset;          // added to the source's brick offset: the target's offset in its own brick
  int brick;           // which of the 3x3x3 neighbouring bricks holds the target (13: the same one)
  uint32_t dir;        // index of the link in the stencil (stored in the target's key)
  double fx, fy, fz;   // the link in unit space (Grid::axisScale), so site distances need no conversions
  bool propagates_to;  // true when the target always propagates (every cubic stencil)
};

class LinkTables {
 public:
  /// `scale`: the grid's axis scales (unit space per voxel step, Grid::axisScale).
  LinkTables(const Stencil& stencil, const Vec3d& scale);

  /// Every link of the stencil, in stencil order (brick 13, offsets relative to an interior source).
  const std::vector<Link>& all() const { return links_; }
  /// The position class of a brick-local coordinate along one axis: 0, 1..6 or 7.
  static int positionClass(int v) { return v == 0 ? 0 : (v == kBrickSize - 1 ? 2 : 1); }
  [[gnu::always_inline]] static int tableOf(const Coord& local, uint32_t dir) {
    return (positionClass(local.z) * 9 + positionClass(local.y) * 3 + positionClass(local.x)) * 32 + int(dir);
  }
  [[gnu::always_inline]] const std::vector<Link>& linksFor(const Coord& local, uint32_t dir) const {
    return tables_[tableOf(local, dir)];
  }
  /// The neighbouring bricks (bit Link::brick, never 13) that linksFor(local, dir) reaches: a push looks them up
  /// once, before its links.
  [[gnu::always_inline]] uint32_t bricksFor(const Coord& local, uint32_t dir) const { return bricks_[tableOf(local, dir)]; }

 private:
  std::vector<Link> links_;
  uint32_t bricks_[27 * 32] = {};
  // links_ specialised for each position class of the source in its brick (per axis local 0, 1..6 or 7) and each
  // arrival direction: links whose target the previous offerer already reached with the same site are dropped.
  std::vector<Link> tables_[27 * 32];
};

}  // namespace distband::band_internal
