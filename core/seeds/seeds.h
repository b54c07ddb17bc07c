// Seeds: what the engine propagates from — the initial band and the table of sites it refers to.
// Contract: a seed source (points, volume, mesh: see core/seeds/) builds a Seeds for one Grid. The engine reads
// it without modifying it, from many threads at once.
//   * A *site* is a closest-feature candidate. kPoint sites are positions in unit space (core/grid.h: index space on a
//     cubic grid, voxel units); kTriangle sites are triangles (unit space, TriangleSites) and a voxel's distance to
//     one is the exact point–triangle distance.
//   * `band` lists the voxels the propagation starts from, each with its site; the engine computes their
//     distances from the site itself. kNoSite marks a voxel whose distance is 0 and that offers nothing to its
//     neighbours (the interior of a seed volume). With `band_exact` the band's sites are final.
//   * `region` (optional, dense x-fastest, one byte per voxel): propagation never crosses between voxels of
//     different labels (used for signed seed volumes, where inside and outside have different site sets).
//   * `site_offset`: sites are in the unit space of a larger grid of which the engine's grid is the window at
//     site_offset (a tile of a query split over servers); voxel c is at (c + site_offset) * axis scale there. Zero
//     otherwise.
//   * Closest features (BandOptions::closest_features): kSiteIndex reports site_feature[site], or the site index
//     itself when site_feature is empty (triangle ids, point indices); kSiteVoxel reports the voxel a point site
//     sits on as its linear index in the engine's grid (Grid::denseIndex; volumes, whose sites are boundary
//     voxels), kNoSite voxels (the seed volume's inside) being their own feature.
//   * `sign` (optional): called on every delivered brick to turn unsigned distances into signed ones
//     (negative inside, OpenVDB's convention); it receives each masked voxel's site. `sign_shares` (with it): how
//     many of the voxels signed so far each test decided (SignShares), for reports.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

#include "core/brick.h"
#include "core/first_touch.h"
#include "core/grid.h"
#include "core/types.h"

namespace distband {

inline constexpr uint32_t kNoSite = std::numeric_limits<uint32_t>::max() - 1;

enum class SiteKind { kPoint, kTriangle };

/// How the delivered voxels of a signed mesh field were signed: each voxel counts once, under the test that decided
/// it (core/seeds/mesh_sign.h).
struct SignShares {
  int64_t pseudonormal = 0;       ///< the pseudonormal test
  int64_t winding_certified = 0;  ///< the winding number, one query a brick where it provably fixes every voxel's sign
  int64_t winding_per_voxel = 0;  ///< the winding number, per voxel (a query, or inside a queried voxel's safe ball)
  int64_t parity = 0;             ///< ray parity
  int64_t total() const { return pseudonormal + winding_certified + winding_per_voxel + parity; }
  SignShares& operator+=(const SignShares& o) {
    pseudonormal += o.pseudonormal;
    winding_certified += o.winding_certified;
    winding_per_voxel += o.winding_per_voxel;
    parity += o.parity;
    return *this;
  }
  friend bool operator==(const SignShares&, const SignShares&) = default;
};

/// Triangle sites: unit-space vertices and each triangle's three vertex ids, shared (with the mesh's sign tables) and
/// immutable: 12 bytes a triangle and 24 a vertex (~24 a triangle on a closed mesh) where three copied corners took
/// 72, the largest table of a multi-million-triangle mesh's run. Copies share the tables.
class TriangleSites {
 public:
  using Corners = std::array<uint32_t, 3>;
  TriangleSites() = default;
  /// Every corner must name one of `vertices` (the mesh seeds check this first).
  TriangleSites(std::shared_ptr<const std::vector<Vec3d>> vertices, std::shared_ptr<const std::vector<Corners>> corners)
      : vertices_(std::move(vertices)),
        corners_(std::move(corners)),
        v_(vertices_->data()),
        c_(corners_->data()),
        count_(corners_->size()) {}
  size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  /// Triangle t's corners (t < size()).
  [[gnu::always_inline]] std::array<Vec3d, 3> operator[](size_t t) const {
    const Corners& c = c_[t];
    return {v_[c[0]], v_[c[1]], v_[c[2]]};
  }

 private:
  std::shared_ptr<const std::vector<Vec3d>> vertices_;
  std::shared_ptr<const std::vector<Corners>> corners_;
  const Vec3d* v_ = nullptr;  // the tables' data, read without the shared pointers' indirection
  const Corners* c_ = nullptr;
  size_t count_ = 0;
};

struct BandVoxel {
  Coord voxel;
  uint32_t site = kNoSite;
};

/// A band's storage: mapped on its own when it spans 2 MiB or more (MappedAllocator), so that when the engine gives
/// it back after its first step its pages return to the system at once, where the bricks the engine maps next reuse
/// them; in malloc's heap they stayed resident and unused beside the bricks until the output took them (a 512^3
/// teapot run: 16 of its 84 MiB peak).
using BandVoxels = std::vector<BandVoxel, MappedAllocator<BandVoxel>>;

struct Seeds {
  SiteKind kind = SiteKind::kPoint;
  std::vector<Vec3d> points;                    ///< kPoint sites, unit space
  TriangleSites triangles;                      ///< kTriangle sites, unit space
  BandVoxels band;
  /// True when every band voxel's site is already its closest site (mesh and volume seeds): the engine then
  /// never offers anything to band voxels, which saves most of the work of thin bands.
  bool band_exact = false;
  std::shared_ptr<const std::vector<uint8_t>> region;  ///< null, or grid.voxelCount() labels
  Coord site_offset{};  ///< where the engine's grid sits in the sites' index space (see above)
  enum class FeatureKind { kSiteIndex, kSiteVoxel };
  FeatureKind feature_kind = FeatureKind::kSiteIndex;
  std::vector<uint32_t> site_feature;  ///< kSiteIndex: the feature of each site (empty: the site index)
  /// Signs the masked values of `brick` in place; `sites[i]` is the site of voxel offset i (kNoSite if none).
  std::function<void(Brick& brick, const uint32_t* sites)> sign;
  std::function<SignShares()> sign_shares;  ///< with `sign`: the voxels it signed so far, by test

  size_t siteCount() const { return kind == SiteKind::kPoint ? points.size() : triangles.size(); }
};

}  // namespace distband
