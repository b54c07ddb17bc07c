// Bvh: a bounding-volume hierarchy over primitives known by their boxes, searched for the primitive nearest a point —
// the index the point queries' searches share (core/points/triangle_bvh.h over triangles, core/points/point_set.h
// over seed points and seed voxel centres).
// Contract:
//   * build() takes one box per primitive (float, each rounded outward from the primitive's double coordinates so
//     it contains the primitive exactly) and splits them by the surface-area heuristic into a binary tree whose
//     leaves hold at most `leaf_size` primitives, then collapses it into nodes of four children (one step tests four
//     boxes); order() lists the primitives in leaf order (leaf ranges index it).
//     The build runs on the caller's TBB arena and polls `interrupter` (then it returns its status).
//   * nearest() visits the leaves nearest-first by their boxes and skips every subtree whose box lies farther than
//     the current best squared distance, which the leaf visitor lowers as it finds primitives: the visitor therefore
//     sees every primitive that can be at least as near as the nearest one (ties included), so a search is exact
//     when the visitor computes exact distances. Start *best2 at the limit squared to prune beyond a limit.
//   * Pruning compares a lower bound on the box's squared distance (see lowerDistances2; the corners contain the
//     primitive) with the best: a box is skipped only when it is truly farther, so no primitive at the best distance is
//     lost.
// Immutable once built; nearest() is thread-safe and allocates nothing.
#pragma once

#include <algorithm>
#include <iterator>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/interrupter.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

/// An axis-aligned box in float, containing what it bounds.
struct BvhBox {
  float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity()};
  float hi[3] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity()};

  /// Grows the box to contain p (rounded outward to float).
  void add(const Vec3d& p) {
    const double c[3] = {p.x, p.y, p.z};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], down(c[a]));
      hi[a] = std::max(hi[a], up(c[a]));
    }
  }
  void add(const BvhBox& b) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], b.lo[a]);
      hi[a] = std::max(hi[a], b.hi[a]);
    }
  }
  /// The largest float <= v, and the smallest float >= v.
  static float down(double v) {
    const float f = float(v);
    return double(f) > v ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
  }
  static float up(double v) {
    const float f = float(v);
    return double(f) < v ? std::nextafter(f, std::numeric_limits<float>::infinity()) : f;
  }
};

class Bvh {
 public:
  /// A leaf's primitives: order()[begin], ..., order()[begin + count - 1].
  static constexpr uint32_t kLeaf = 0x80000000u;

  /// Builds the tree over `boxes` (at least one). kResourceExhausted beyond 2^31 - 1 primitives.
  static Status build(const std::vector<BvhBox>& boxes, int leaf_size, const Interrupter* interrupter, Bvh* out);

  /// Visits the leaves that can hold a primitive within sqrt(*best2) of p, nearest box first:
  /// leaf(begin, count) examines primitives order()[begin .. begin + count) and lowers *best2 when it finds a
  /// nearer one (the visitor holds best2 by reference).
  template <typename Leaf>
  void nearest(const Vec3d& p, double* best2, Leaf&& leaf) const {
    if (nodes_.empty() || distance2(root_, p) > *best2) return;
    const Query q(p);
    struct Entry {
      uint32_t node;
      double d2;
    };
    Entry stack[kMaxDepth * (kWidth - 1)];
    int top = 0;
    uint32_t current = 0;
    for (;;) {
      const Node& n = nodes_[current];
      // The children within the best distance, nearest first (an insertion sort of at most four).
      double d[kWidth];
      lowerDistances2(n, q, d);
      int near[kWidth], count = 0;
      for (int c = 0; c < kWidth; ++c) {
        if (n.child[c] == kEmpty || d[c] > *best2) continue;
        int k = count++;
        for (; k > 0 && d[near[k - 1]] > d[c]; --k) near[k] = near[k - 1];
        near[k] = c;
      }
      uint32_t next = kEmpty;
      int pushed_from = top;
      for (int k = 0; k < count; ++k) {
        const int c = near[k];
        if (d[c] > *best2) continue;
        if (n.child[c] & kLeaf) {
          leaf(n.child[c] & ~kLeaf, n.count[c]);
        } else if (next == kEmpty) {
          next = n.child[c];
        } else {
          stack[top++] = {n.child[c], d[c]};
        }
      }
      // Popped nearest first: the pushed siblings go on the stack farthest first.
      std::reverse(stack + pushed_from, stack + top);
      if (next != kEmpty) {
        current = next;
        continue;
      }
      while (top > 0 && stack[top - 1].d2 > *best2) --top;
      if (top == 0) return;
      current = stack[--top].node;
    }
  }

  const std::vector<uint32_t>& order() const { return order_; }
  const BvhBox& bounds() const { return root_; }
  uint64_t memoryBytes() const { return nodes_.capacity() * sizeof(Node) + order_.capacity() * sizeof(uint32_t); }
  /// An upper bound on memoryBytes() and on the build's scratch for `primitives` primitives.
  static uint64_t estimateBytes(uint64_t primitives) {
    return primitives * (sizeof(Node) + 2 * sizeof(uint32_t) + sizeof(BvhBox) + 3 * sizeof(float) + 64);
  }

 private:
  static constexpr int kWidth = 4;
  /// The deepest tree the builder makes (Builder: the median split below depth 48 halves what is left).
  static constexpr int kMaxDepth = 48 + 32;
  static constexpr uint32_t kEmpty = 0xFFFFFFFFu;
  /// A node holds its (up to) four children's boxes: a step reads two cache lines and tests four boxes.
  struct alignas(64) Node {
    float lo[3][kWidth], hi[3][kWidth];  ///< [axis][child]
    uint32_t child[kWidth];              ///< a node's index, kLeaf | a leaf's first position in order_, or kEmpty
    uint32_t count[kWidth];              ///< a leaf's primitive count
  };
  /// p as float bounds: lo <= p <= hi on every axis.
  struct Query {
    explicit Query(const Vec3d& p)
        : lo{BvhBox::down(p.x), BvhBox::down(p.y), BvhBox::down(p.z)},
          hi{BvhBox::up(p.x), BvhBox::up(p.y), BvhBox::up(p.z)} {}
    float lo[3], hi[3];
  };
  /// Lower bounds on the squared distances from the query to a node's four boxes, computed four at a time in float:
  /// the query's float bracket makes each difference a lower bound before rounding; rounding (a relative 2^-24 per
  /// operation, five operations) can only raise it by less than 2^-20, so the result less that share is a lower
  /// bound still — a box is skipped only when it lies truly farther than the best.
  static void lowerDistances2(const Node& n, const Query& q, double* out) {
    constexpr float kShare = 1.0f - 1.0f / (1 << 19);
#if defined(__SSE2__)
    __m128 sum = _mm_setzero_ps();
    for (int a = 0; a < 3; ++a) {
      const __m128 below = _mm_sub_ps(_mm_load_ps(n.lo[a]), _mm_set1_ps(q.hi[a]));
      const __m128 above = _mm_sub_ps(_mm_set1_ps(q.lo[a]), _mm_load_ps(n.hi[a]));
      const __m128 gap = _mm_max_ps(_mm_max_ps(below, above), _mm_setzero_ps());
      sum = _mm_add_ps(sum, _mm_mul_ps(gap, gap));
    }
    alignas(16) float d[kWidth];
    _mm_store_ps(d, _mm_mul_ps(sum, _mm_set1_ps(kShare)));
    for (int c = 0; c < kWidth; ++c) out[c] = d[c];
#else
    for (int c = 0; c < kWidth; ++c) {
      float sum = 0;
      for (int a = 0; a < 3; ++a) {
        const float gap = std::max({n.lo[a][c] - q.hi[a], q.lo[a] - n.hi[a], 0.0f});
        sum += gap * gap;
      }
      out[c] = sum * kShare;
    }
#endif
  }
  static double distance2(const BvhBox& b, const Vec3d& p) {
    const double dx = std::max({double(b.lo[0]) - p.x, 0.0, p.x - double(b.hi[0])});
    const double dy = std::max({double(b.lo[1]) - p.y, 0.0, p.y - double(b.hi[1])});
    const double dz = std::max({double(b.lo[2]) - p.z, 0.0, p.z - double(b.hi[2])});
    return dx * dx + dy * dy + dz * dz;
  }

  struct Builder;
  std::vector<Node> nodes_;  ///< nodes_[0] is the root (a node, even above a single leaf)
  std::vector<uint32_t> order_;
  BvhBox root_;
};

}  // namespace distband
