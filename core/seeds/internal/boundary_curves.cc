#include "core/seeds/internal/boundary_curves.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace distband::seeds_internal {
namespace {

// Distances are to the edges themselves: a long boundary edge passes far from its vertices.
constexpr uint32_t kTurnLeaf = 2;  // the tree's leaves: a leaf's ball is at most one piece long
constexpr double kInfinity = std::numeric_limits<double>::infinity();

}  // namespace

BoundaryCurves::Piece::Piece(const Vec3d& from, const Vec3d& to, int32_t edge_net)
    : a(from), ab(to - from), net(float(std::abs(edge_net))) {
  const double len2 = ab.lengthSqr();
  inverse_len2 = len2 > 0 ? 1 / len2 : 0;
  length = float(std::sqrt(len2));
}

// Off the surface the winding number's gradient is a line integral over the boundary chain (the Biot-Savart law for
// a unit current around it): grad w(x) = (1/4 pi) sum over the chain's edges of net x the integral of
// (y - x) x dy / |y - x|^3, whose integrand along a straight piece has length rho dl / |y - x|^3, rho the distance
// from x to the piece's line. At points at least d from the piece and at most rho from its line that is at most
// rho / d^3 (and 1 / d^2, as rho <= |y - x|) a unit of length; over the whole line the integral of
// rho / (rho^2 + l^2)^(3/2) is 2 / rho, and it is at most 1 / d when the piece stops short of the foot of x, so
// never more than 2 / d.
double BoundaryCurves::Piece::turn(double d, double rho) const {
  return double(net) * std::min(double(length) * std::min(1.0, rho / d) / (d * d), 2 / d);
}

void BoundaryCurves::build(std::span<const Vec3d> vertices, std::span<const ChainEdge> chain, uint64_t max_pieces) {
  // Counted first, in doubles: an edge between far-apart vertices of an untrusted mesh needs more pieces than an
  // integer holds (or infinitely many); once the sum is within the budget, every count fits an int.
  const auto piecesOf = [&](const ChainEdge& edge) {
    return std::max(1.0, std::ceil((vertices[edge.b] - vertices[edge.a]).length() / kPieceLength));
  };
  double pieces = 0;
  for (const ChainEdge& edge : chain) pieces += piecesOf(edge);
  if (!(pieces <= double(max_pieces))) {
    everywhere_ = true;
    return;
  }
  pieces_.reserve(size_t(pieces));
  for (const ChainEdge& edge : chain) {
    const Vec3d a = vertices[edge.a], b = vertices[edge.b];
    const int n = int(piecesOf(edge));
    for (int k = 0; k < n; ++k)
      pieces_.emplace_back(a + (b - a) * (double(k) / n), a + (b - a) * (double(k + 1) / n), edge.net);
  }
  if (pieces_.empty()) return;
  buildTree();  // reorders the pieces
}

void BoundaryCurves::buildTree() {
  // Each node's pieces halved along the longest extent of their midpoints, down to kTurnLeaf a leaf.
  nodes_.reserve(2 * pieces_.size());
  const auto mid = [&](uint32_t k) { return pieces_[k].a + pieces_[k].ab * 0.5; };
  const auto build = [&](const auto& self, uint32_t node, uint32_t begin, uint32_t end) -> void {
    Vec3d lo = pieces_[begin].a, hi = lo, mid_lo = mid(begin), mid_hi = mid_lo;
    double net_length = 0;
    for (uint32_t k = begin; k < end; ++k) {
      const Piece& piece = pieces_[k];
      for (const Vec3d& e : {piece.a, piece.a + piece.ab}) {
        lo = {std::min(lo.x, e.x), std::min(lo.y, e.y), std::min(lo.z, e.z)};
        hi = {std::max(hi.x, e.x), std::max(hi.y, e.y), std::max(hi.z, e.z)};
      }
      const Vec3d m = mid(k);
      mid_lo = {std::min(mid_lo.x, m.x), std::min(mid_lo.y, m.y), std::min(mid_lo.z, m.z)};
      mid_hi = {std::max(mid_hi.x, m.x), std::max(mid_hi.y, m.y), std::max(mid_hi.z, m.z)};
      net_length += double(piece.net) * double(piece.length);
    }
    Node n{(lo + hi) * 0.5, 0, net_length, begin, end, 0};
    for (uint32_t k = begin; k < end; ++k)  // a piece is a segment: within the ball when both its ends are
      n.radius =
          std::max({n.radius, (pieces_[k].a - n.center).length(), (pieces_[k].a + pieces_[k].ab - n.center).length()});
    if (end - begin > kTurnLeaf) {
      const Vec3d e = mid_hi - mid_lo;
      const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
      const auto key = [&](const Piece& piece) {
        const Vec3d m = piece.a + piece.ab * 0.5;
        return axis == 0 ? m.x : (axis == 1 ? m.y : m.z);
      };
      const uint32_t half = begin + (end - begin) / 2;
      std::nth_element(pieces_.begin() + begin, pieces_.begin() + half, pieces_.begin() + end,
                       [&](const Piece& x, const Piece& y) { return key(x) < key(y); });
      n.first_child = uint32_t(nodes_.size());
      nodes_.resize(nodes_.size() + 2);
      self(self, n.first_child, begin, half);
      self(self, n.first_child + 1, half, end);
    }
    nodes_[node] = n;
  };
  nodes_.resize(1);
  build(build, 0, 0, uint32_t(pieces_.size()));
}

uint64_t BoundaryCurves::memoryBytes() const {
  return pieces_.capacity() * sizeof(Piece) + nodes_.capacity() * sizeof(Node);
}

void BoundaryCurves::findNear(const Vec3d& center, double reach, Near* near) const {
  near->center = center;
  near->cap = kInfinity;
  near->pieces.clear();
  near->turn_far = 0;
  near->turn_pieces.clear();
  if (pieces_.empty()) return;
  // The turn rate's split. A node far from the ball (more than twice its reach) and small against that distance is
  // bounded whole (its pieces lie within 2 radius of its distance d, so its bound is at most (1 + 2 kOpen)^2 = 2.25
  // times theirs); the pieces of nearer leaves are listed, each bounded again for the smaller balls inside this one
  // (a certificate's box, a voxel's ball), unless they too are more than twice the reach away: a smaller ball inside
  // would gain little.
  constexpr double kOpen = 0.25;
  std::array<uint32_t, 64> stack;
  int top = 0;
  stack[size_t(top++)] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[size_t(--top)]];
    const double d = (center - node.center).length() - node.radius - reach;
    if (d > 2 * reach && node.radius <= kOpen * d) {
      near->turn_far += node.net_length / (d * d);
    } else if (node.first_child != 0 && top + 2 <= int(stack.size())) {
      stack[size_t(top++)] = node.first_child + 1;
      stack[size_t(top++)] = node.first_child;
    } else {
      for (uint32_t k = node.begin; k < node.end; ++k) {
        const Piece& piece = pieces_[k];
        const double dk = std::sqrt(piece.distance2(center)) - reach;
        const double rho = std::sqrt(piece.lineDistance2(center)) + reach;
        if (dk > 2 * reach)
          near->turn_far += piece.turn(dk, rho);
        else
          near->turn_pieces.push_back({k, dk, rho});
      }
    }
  }
  // The distance's pieces: the nearest, found in the tree (a node's ball bounds its pieces' distance from below; the
  // nearer child first), then every piece within 2 reach of its distance: no other is anybody's nearest within reach.
  near->pieces.reserve(64);  // grown by doubling from one, it was several allocations a brick
  const auto lowerBound = [&](const Node& node) { return (center - node.center).length() - node.radius; };
  double best2 = kInfinity;
  top = 0;
  stack[size_t(top++)] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[size_t(--top)]];
    const double lower = lowerBound(node);
    if (lower > 0 && lower * lower >= best2) continue;
    if (node.first_child != 0 && top + 2 <= int(stack.size())) {
      const bool second_nearer = (center - nodes_[node.first_child + 1].center).lengthSqr() <
                                 (center - nodes_[node.first_child].center).lengthSqr();
      stack[size_t(top++)] = node.first_child + (second_nearer ? 0 : 1);
      stack[size_t(top++)] = node.first_child + (second_nearer ? 1 : 0);
    } else {
      for (uint32_t k = node.begin; k < node.end; ++k) best2 = std::min(best2, pieces_[k].distance2(center));
    }
  }
  const double keep = std::sqrt(best2) + 2 * reach;
  near->cap = keep;  // every piece left out is farther
  top = 0;
  stack[size_t(top++)] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[size_t(--top)]];
    if (lowerBound(node) > keep) continue;
    if (node.first_child != 0 && top + 2 <= int(stack.size())) {
      stack[size_t(top++)] = node.first_child + 1;
      stack[size_t(top++)] = node.first_child;
    } else {
      for (uint32_t k = node.begin; k < node.end; ++k) {
        const double d2 = pieces_[k].distance2(center);
        if (d2 <= keep * keep) near->pieces.emplace_back(k, d2);
      }
    }
  }
}

double BoundaryCurves::distance(const Near& near, const Vec3d& p, double radius) const {
  if (everywhere_) return 0;
  if (pieces_.empty()) return kFar;
  double best2 = kInfinity;
  for (const auto& [k, d2] : near.pieces) best2 = std::min(best2, pieces_[k].distance2(p));
  const double cap = near.cap - (p - near.center).length();
  return std::max(0.0, std::min(std::sqrt(best2), cap) - radius);
}

// The bound sums the pieces' (Piece::turn) and the far nodes' (a node at distance d: at most sum |net| len / d^2,
// 4 pi times). Sound everywhere: at the centre of a circular rim of radius B the gradient is 1 / (2 B), and the
// pieces' sum gives about that; the bound it replaced (2026-11-29), 1 / (pi B) through the nearest curve alone, was
// short by a factor of 1.6 there, and several curves turning the winding number the same way add up.
double BoundaryCurves::turnRate(const Near& near, const Vec3d& p, double radius, double cap) const {
  if (everywhere_) return kInfinity;
  const double sum_cap = cap * (4 * std::numbers::pi);
  double sum = near.turn_far;
  for (const Near::TurnPiece& listed : near.turn_pieces) {
    const Piece& piece = pieces_[listed.piece];
    // Both balls' bounds hold at the points that matter, in the two.
    const double d = std::max(listed.distance, std::sqrt(piece.distance2(p)) - radius);
    if (d <= 0) return kInfinity;
    sum += piece.turn(d, std::min(listed.line_distance, std::sqrt(piece.lineDistance2(p)) + radius));
    if (sum >= sum_cap) return kInfinity;
  }
  return sum >= sum_cap ? kInfinity : sum / (4 * std::numbers::pi);
}

}  // namespace distband::seeds_internal
