// The curves the generalized winding number turns around without crossing the surface: a mesh's boundary chain
// (core/mesh/winding_number.h: meshBoundaryChain; boundary edges, non-manifold ones, edges two faces run the same
// way), cut into straight pieces. The winding sign's certificates read two bounds from them (core/seeds/mesh_sign.cc):
// how far a ball is from every curve, and how fast the winding number can turn inside it.
// Contract: build() once, then any number of threads query; a query first gathers the pieces near its brick
// (findNear), then asks about balls inside that brick's ball. Coordinates are the grid's index frame (frame units).
// Not part of the public API (only core/seeds/mesh_sign.cc and tests include it).
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "core/mesh/winding_number.h"
#include "core/types.h"

namespace distband::seeds_internal {

class BoundaryCurves {
 public:
  /// distance()'s answer when there are no curves (frame units).
  static constexpr double kFar = 1e6;
  /// The longest piece (frame units).
  static constexpr double kPieceLength = 16;
  /// Bytes held a piece, at most: the piece (64) and fewer than two nodes of the tree (112).
  static constexpr uint64_t kBytesPerPiece = 64 + 112;

  /// Cuts the chain's edges (vertex ids into `vertices`) into pieces of at most kPieceLength. Past `max_pieces`
  /// (long thin triangles at the boundary, a soup of them, would make pieces without bound) it keeps none and takes
  /// the curves to pass everywhere: distance() is 0 and turnRate() infinite for every ball.
  void build(std::span<const Vec3d> vertices, std::span<const ChainEdge> chain, uint64_t max_pieces);

  bool everywhere() const { return everywhere_; }
  uint64_t memoryBytes() const;

  /// The pieces that matter to balls within `reach` of `center` (a brick's), found once for the brick.
  struct Near {
    Vec3d center;
    double cap = 0;                                   // every piece not in `pieces` is at least this far from center
    std::vector<std::pair<uint32_t, double>> pieces;  // a piece, its squared distance from center
    // The turn rate's pieces: those far from the ball of `reach` around center bounded once, in tree nodes
    // (turn_far, 4 pi times a rate), the near ones listed with their distance from that ball (<= 0: within it) and
    // the farthest the ball reaches from their line.
    double turn_far = 0;
    struct TurnPiece {
      uint32_t piece;
      double distance, line_distance;
    };
    std::vector<TurnPiece> turn_pieces;
  };
  void findNear(const Vec3d& center, double reach, Near* near) const;

  /// A lower bound on the distance from every point within `radius` of p to the curves, p within the reach of
  /// near.center; kFar when there are none, 0 when everywhere().
  double distance(const Near& near, const Vec3d& p, double radius) const;

  /// An upper bound on how fast the winding number turns (its gradient's length, per frame unit) off the surface at
  /// every point within `radius` of p and within the reach of near.center: infinity when a curve passes there (or
  /// everywhere()), or as soon as the bound reaches `cap` (where the caller has no use for it).
  double turnRate(const Near& near, const Vec3d& p, double radius, double cap) const;

 private:
  struct Piece {
    Vec3d a, ab;          // from a to a + ab
    double inverse_len2;  // 1 / |ab|^2, 0 for a point
    float length;         // |ab|
    float net;            // |net| of its edge: how many times the chain runs it
    Piece(const Vec3d& from, const Vec3d& to, int32_t edge_net);
    /// The squared distance from p to the piece (every brick and certificate reads a few dozen: no division).
    double distance2(const Vec3d& p) const {
      const Vec3d ap = p - a;
      const double t = std::clamp(ap.dot(ab) * inverse_len2, 0.0, 1.0);
      return (ap - ab * t).lengthSqr();
    }
    /// The squared distance from p to the piece's line.
    double lineDistance2(const Vec3d& p) const {
      const Vec3d ap = p - a;
      return (ap - ab * (ap.dot(ab) * inverse_len2)).lengthSqr();
    }
    /// 4 pi times a bound on the piece's share of the turn rate at points at least `d` (> 0) from it and at most
    /// `rho` from its line.
    double turn(double d, double rho) const;
  };
  /// A binary tree over the pieces: each node a ball around its pieces' range, with the sum of their |net| x length,
  /// leaves of at most kTurnLeaf pieces. The turn rate's far nodes and the distance's search both read it.
  struct Node {
    Vec3d center;
    double radius;
    double net_length;
    uint32_t begin, end;
    uint32_t first_child;  // the two children are first_child and first_child + 1; 0 for a leaf
  };
  static_assert(sizeof(Piece) + 2 * sizeof(Node) <= kBytesPerPiece, "kBytesPerPiece counts 64 + 112");

  void buildTree();

  std::vector<Piece> pieces_;
  std::vector<Node> nodes_;  // the root first
  bool everywhere_ = false;
};

}  // namespace distband::seeds_internal
