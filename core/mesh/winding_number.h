// WindingNumber: the generalized winding number of a triangle mesh (Jacobson et al. 2013), evaluated with a
// Barnes–Hut hierarchy (Barill et al. 2018: dipole and second-order terms) so a query costs O(log T) instead of O(T).
// Contract: built once from triangles (any consistent frame, e.g. index space); w(p) is ~1 inside a closed
// outward-oriented mesh, ~0 outside, and varies smoothly across the holes of an open mesh, so `w > 0.5` is a
// robust inside test. Clusters farther than `beta` times their radius use their far-field expansion to second
// order (the truncation error falls as (radius / distance)^3); near clusters are summed exactly (Van
// Oosterom–Strackee solid angles). principalValue(t) is w on triangle t itself (its own solid angle, 0 there, left
// out): across a consistently oriented sheet w jumps by 1, from principalValue + 1/2 behind it to principalValue -
// 1/2 in front. Triangles are named by their index in the constructor's list. Immutable after construction; queries
// are thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/interrupter.h"
#include "core/types.h"

namespace distband {

class WindingNumber {
 public:
  /// Builds the hierarchy (O(T log T)); `interrupter` is polled while it is built: when it trips, the build stops
  /// early and the object must not be queried.
  explicit WindingNumber(std::vector<std::array<Vec3d, 3>> triangles, double beta = 2.0,
                         const Interrupter* interrupter = nullptr);
  /// w(p), within ~0.01 of the exact sum near a mesh (measured below 0.011 near open meshes).
  double query(const Vec3d& p) const;
  /// w(p) at about half query()'s cost near a mesh, within ~0.05 (measured below 0.042 within 3 voxels of open
  /// meshes at 512^3: tests/core/mesh/winding_number_test.cc): clusters stay expansions up to ten times the
  /// third-order term query() allows. For the side of 1/2 where it is far from 1/2.
  double coarseQuery(const Vec3d& p) const;
  /// w(p) at 0.4-0.5 of coarseQuery()'s cost near a mesh, within ~0.2 (measured below 0.17 within 3 voxels of open
  /// meshes at 512^3): clusters from 1.25 of their radii on stay expansions, up to a hundred times the third-order term
  /// query() allows. For the side of 1/2, or of 0 and 1, where the value is far from it.
  double roughQuery(const Vec3d& p) const;
  /// The query tiers, finest first as above: query(), coarseQuery(), roughQuery().
  enum class Tier { kFine, kCoarse, kRough };
  /// What a tier's query reads for every point within `radius` of `center` (a brick's voxels): the clusters far enough
  /// from the whole ball to be taken whole there, and the leaves summed exactly. A point's value from it is at least as
  /// accurate as the tier's query (every cluster passes the query's test at every point of the ball; the query may
  /// take an ancestor whole), without a traversal per point.
  struct Plan {
    std::vector<uint32_t> far, near;  ///< nodes
    /// What planned() reads, eight lanes to a block (one AVX2 instruction each). The far clusters again in single
    /// precision, centers relative to `origin` (the ball's center); unused lanes hold a cluster of no area far away (a
    /// zero term).
    struct alignas(32) FarLanes {
      float center[3][8], area[3][8], moment[6][8];  ///< [component][lane]
    };
    std::vector<FarLanes> far_lanes;
    /// The near leaves' triangles, two leaves to a block (lanes 0-3 and 4-7; an odd one out leaves 4-7 unused), as
    /// each leaf keeps them: corners relative to its center, and the normal with its squared length.
    struct alignas(32) NearLanes {
      float corner[3][3][8], normal[4][8];  ///< [corner][axis][lane], [axis, then squared length][lane]
      float near_corner[8];                 ///< the leaf's "p at a corner" threshold (kSureCorner2 times its radius^2)
      int32_t used[8];                      ///< all bits set in a lane that holds a triangle
      Vec3d center[2];                      ///< the two leaves' centers
      uint32_t begin[2];                    ///< their first triangles
    };
    std::vector<NearLanes> near_lanes;
    Vec3d origin;
  };
  void plan(const Vec3d& center, double radius, Tier tier, Plan* plan) const;
  /// w(p) from a plan made for a ball that holds p.
  double planned(const Plan& plan, const Vec3d& p) const;
  /// w at triangle t's centroid, t itself left out (the principal value on the surface).
  double principalValue(uint32_t t) const;
  /// The exact sum over all triangles (O(T)); for checks.
  double exact(const Vec3d& p) const;
  /// The most bytes a hierarchy of this many triangles holds, its build included (for memory budgets).
  static uint64_t estimateBytes(uint64_t triangles);
  /// Bytes held (for memory budgets).
  uint64_t memoryBytes() const {
    return tris_.capacity() * sizeof(tris_[0]) + nodes_.capacity() * sizeof(Node) +
           leaves_.capacity() * sizeof(LeafTriangles);
  }

 private:
  struct Node {
    Vec3d center;     ///< area-weighted centroid of the node's triangles
    Vec3d area;       ///< sum of the triangles' area vectors (0.5 * (b - a) x (c - a))
    double abs_area;  ///< sum of the triangles' areas
    /// Second-order moment: the symmetric part of the sum over the triangles of area vector (x) (centroid - center)
    /// (xx, yy, zz, xy, xz, yz), all the second-order term reads (r^T M r and the trace). Single precision: that term
    /// is a correction of at most 1/beta of the dipole's size.
    std::array<float, 6> moment;
    double radius2;   ///< squared radius around center enclosing all their corners
    uint32_t begin, end;    ///< triangle range (leaves)
    uint32_t left, right;   ///< children; a leaf: left 0, right its LeafTriangles in leaves_
  };
  /// A leaf's triangles (at most kLeafSize, in lanes) as single-precision corners relative to the leaf's center, axis
  /// by axis: a near query sums a leaf's solid angles four at a time. Relative to a nearby center single precision
  /// keeps ~1e-7 of the leaf's size, far below the distances at which a query's value can change by its error.
  struct alignas(16) LeafTriangles {
    float corner[3][3][4];  ///< [corner][axis][lane]
    float normal[4][4];     ///< (b - a) x (c - a): [axis][lane], then its squared length by lane
  };
  /// Builds node `id` over triangles [begin, end) of ids_ and, after it, its subtree, numbered depth first.
  void build(uint32_t begin, uint32_t end, uint32_t id);
  /// The nodes of the subtree over this many triangles.
  static uint32_t nodeCount(uint32_t triangles);
  /// A tier's test for taking a cluster whole: the largest third-order term (times 4 pi) and beta^2.
  struct TierParameters {
    double tolerance, beta2;
  };
  TierParameters parameters(Tier tier) const;
  double sum(const Vec3d& p, uint32_t skip, const TierParameters& tp) const;
  /// A cluster's far field at p (times 4 pi); a leaf's half solid angles at p, triangle `skip` left out.
  double farTerm(const Node& n, const Vec3d& p) const;
  double leafHalfAngles(const Node& n, const Vec3d& p, uint32_t skip) const;
  double plannedLanes(const Plan& plan, const Vec3d& p) const;  ///< planned(), in this file only (its clones)
  double solidAngle(const std::array<Vec3d, 3>& t, const Vec3d& p) const;

  std::vector<std::array<Vec3d, 3>> tris_;  ///< in hierarchy order
  std::vector<uint32_t> ids_;               ///< ids_[i]: the constructor's index of tris_[i]
  std::vector<uint32_t> position_;          ///< position_[id]: where triangle id sits in tris_
  std::vector<Node> nodes_;
  std::vector<LeafTriangles> leaves_;  ///< by leaf, in node order
  std::vector<Vec3d> centroids_;  ///< during the build only: by the constructor's index
  double beta2_;
  const Interrupter* interrupter_ = nullptr;  ///< during the build only
};

/// An edge of a mesh's boundary as a chain (vertex ids a < b): an edge the triangles do not use as a consistently
/// oriented manifold edge (used once, three or more times, or twice the same way), with how many triangles run it from
/// a to b less how many run it from b to a (`net`; 0 for an edge that is non-manifold but balanced).
struct ChainEdge {
  uint32_t a, b;
  int32_t net;
  uint32_t uses;
};
/// The boundary chain of `triangles` (vertex ids below kDirectedKeyVertexLimit, core/mesh/triangle_mesh.h), sorted by
/// (a, b). O(T log T), in parallel.
std::vector<ChainEdge> meshBoundaryChain(std::span<const std::array<uint32_t, 3>> triangles);

/// Fans that close a boundary chain: the chain (its edges taken |net| times, in the direction of net's sign) split
/// into closed walks, each closed by fans of small triangles (one from near the centroid of each arc of a few edges,
/// then the same over the shorter walk through the arcs' ends and the fans' apexes). The fans and the mesh have the
/// same boundary, so off both their winding numbers differ by an integer: w(mesh) = w(fans) + k, and an estimate of
/// w(mesh) within 1/2 gives k. About 4/3 sum |net| triangles; empty when the chain is empty.
std::vector<std::array<Vec3d, 3>> boundaryFans(std::span<const Vec3d> vertices, std::span<const ChainEdge> chain);

}  // namespace distband
