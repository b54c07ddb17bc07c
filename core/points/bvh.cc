#include "core/points/bvh.h"

#include <atomic>
#include <numeric>

#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

namespace distband {
namespace {

constexpr int kBins = 16;
/// Below this depth the split is the surface-area heuristic's; deeper, the median's (which halves the count), so the
/// depth stays below Bvh::nearest's stack (48 + log2(2^31)).
constexpr int kSahDepth = 48;
/// Subtrees of at least this many primitives are built as parallel tasks (and poll the interrupter).
constexpr uint32_t kParallelPrimitives = 4096;

float area(const BvhBox& b) {
  const float dx = b.hi[0] - b.lo[0], dy = b.hi[1] - b.lo[1], dz = b.hi[2] - b.lo[2];
  if (!(dx >= 0 && dy >= 0 && dz >= 0)) return 0;
  return 2 * (dx * dy + dy * dz + dz * dx);
}

}  // namespace

/// The binary tree the builder makes, collapsed into Bvh's four-wide nodes afterwards.
struct BinaryNode {
  BvhBox box[2];
  uint32_t child[2];  ///< a node's index, or Bvh::kLeaf | a leaf's first position
  uint32_t count[2];
};

struct Bvh::Builder {
  const std::vector<BvhBox>& boxes;
  const int leaf_size;
  const Interrupter* interrupter;
  std::vector<std::array<float, 3>> centroids;
  std::vector<uint32_t>& refs;
  std::vector<BinaryNode> nodes;
  std::atomic<uint32_t> next_node{0};
  std::atomic<bool> stopped{false};

  struct Built {
    uint32_t child = 0, count = 0;
    BvhBox box;
  };

  Built leaf(uint32_t begin, uint32_t end) const {
    Built b;
    b.child = kLeaf | begin;
    b.count = end - begin;
    for (uint32_t i = begin; i < end; ++i) b.box.add(boxes[refs[i]]);
    return b;
  }

  /// Where the range [begin, end) splits: the surface-area heuristic over binned centroids, or the median.
  uint32_t split(uint32_t begin, uint32_t end, int depth) {
    float clo[3], chi[3];
    for (int a = 0; a < 3; ++a) clo[a] = std::numeric_limits<float>::infinity(), chi[a] = -clo[a];
    for (uint32_t i = begin; i < end; ++i)
      for (int a = 0; a < 3; ++a) {
        clo[a] = std::min(clo[a], centroids[refs[i]][a]);
        chi[a] = std::max(chi[a], centroids[refs[i]][a]);
      }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (chi[a] - clo[a] > chi[axis] - clo[axis]) axis = a;
    const float extent = chi[axis] - clo[axis];
    const uint32_t mid = begin + (end - begin) / 2;
    auto median = [&] {
      std::nth_element(refs.begin() + begin, refs.begin() + mid, refs.begin() + end,
                       [&](uint32_t x, uint32_t y) { return centroids[x][axis] < centroids[y][axis]; });
      return mid;
    };
    if (!(extent > 0)) return mid;  // every centroid in one place: any split is as good
    if (depth >= kSahDepth) return median();
    auto binOf = [&](uint32_t ref) {
      return std::min(kBins - 1, int((centroids[ref][axis] - clo[axis]) * (kBins / extent)));
    };
    BvhBox bin_box[kBins];
    uint32_t bin_count[kBins] = {};
    for (uint32_t i = begin; i < end; ++i) {
      const int b = binOf(refs[i]);
      bin_box[b].add(boxes[refs[i]]);
      ++bin_count[b];
    }
    float right_area[kBins];
    uint32_t right_count[kBins];
    BvhBox acc;
    uint32_t count = 0;
    for (int b = kBins - 1; b > 0; --b) {
      acc.add(bin_box[b]);
      count += bin_count[b];
      right_area[b] = area(acc);
      right_count[b] = count;
    }
    acc = BvhBox();
    count = 0;
    int best = -1;
    float best_cost = std::numeric_limits<float>::infinity();
    for (int b = 1; b < kBins; ++b) {  // left: bins [0, b)
      acc.add(bin_box[b - 1]);
      count += bin_count[b - 1];
      if (count == 0 || right_count[b] == 0) continue;
      const float cost = area(acc) * float(count) + right_area[b] * float(right_count[b]);
      if (cost < best_cost) best_cost = cost, best = b;
    }
    if (best < 0) return median();
    const auto at = std::partition(refs.begin() + begin, refs.begin() + end,
                                   [&](uint32_t ref) { return binOf(ref) < best; });
    const uint32_t s = uint32_t(at - refs.begin());
    return s == begin || s == end ? median() : s;
  }

  Built build(uint32_t begin, uint32_t end, int depth) {
    if (end - begin <= uint32_t(leaf_size)) return leaf(begin, end);
    if (end - begin >= kParallelPrimitives && isInterrupted(interrupter)) stopped = true;
    if (stopped) return leaf(begin, begin);
    const uint32_t index = next_node++;
    const uint32_t s = split(begin, end, depth);
    Built left, right;
    if (end - begin >= kParallelPrimitives) {
      tbb::task_group group;
      group.run([&] { left = build(begin, s, depth + 1); });
      right = build(s, end, depth + 1);
      group.wait();
    } else {
      left = build(begin, s, depth + 1);
      right = build(s, end, depth + 1);
    }
    setChildren(index, left, right);
    Built b;
    b.child = index;
    b.box = left.box;
    b.box.add(right.box);
    return b;
  }

  void setChildren(uint32_t index, const Built& left, const Built& right) {
    BinaryNode& n = nodes[index];
    const Built* c[2] = {&left, &right};
    for (int k = 0; k < 2; ++k) {
      n.box[k] = c[k]->box;
      n.child[k] = c[k]->child;
      n.count[k] = c[k]->count;
    }
  }

  /// Makes the four-wide node of binary node `b` into wide[index]: its two children, then, while a slot is free, the
  /// inner child of the largest box replaced by its own two children.
  void collapse(uint32_t b, uint32_t index, std::vector<Node>& wide) {
    struct Slot {
      BvhBox box;
      uint32_t child, count;
    };
    Slot slots[kWidth];
    int used = 0;
    for (int k = 0; k < 2; ++k) slots[used++] = {nodes[b].box[k], nodes[b].child[k], nodes[b].count[k]};
    while (used < kWidth) {
      int pick = -1;
      for (int k = 0; k < used; ++k)
        if (!(slots[k].child & kLeaf) && (pick < 0 || area(slots[k].box) > area(slots[pick].box))) pick = k;
      if (pick < 0) break;
      const BinaryNode& inner = nodes[slots[pick].child];
      slots[pick] = {inner.box[0], inner.child[0], inner.count[0]};
      slots[used++] = {inner.box[1], inner.child[1], inner.count[1]};
    }
    Node n;
    for (int k = 0; k < kWidth; ++k) {
      const bool real = k < used;
      for (int a = 0; a < 3; ++a) {
        n.lo[a][k] = real ? slots[k].box.lo[a] : BvhBox().lo[a];
        n.hi[a][k] = real ? slots[k].box.hi[a] : BvhBox().hi[a];
      }
      n.child[k] = real ? slots[k].child : kEmpty;
      n.count[k] = real ? slots[k].count : 0;
    }
    // Inner children get their wide nodes next (depth first, so a subtree's nodes lie together).
    for (int k = 0; k < used; ++k)
      if (!(n.child[k] & kLeaf)) {
        const uint32_t child_index = uint32_t(wide.size());
        wide.emplace_back();
        const uint32_t binary_child = n.child[k];
        n.child[k] = child_index;
        wide[index] = n;
        collapse(binary_child, child_index, wide);
      }
    wide[index] = n;
  }
};

Status Bvh::build(const std::vector<BvhBox>& boxes, int leaf_size, const Interrupter* interrupter, Bvh* out) {
  if (boxes.empty()) return Status::InvalidArgument("a search over no primitives");
  if (boxes.size() >= kLeaf)
    return Status::ResourceExhausted(
        fmt::format("{} primitives, more than a search holds ({})", boxes.size(), kLeaf - 1));
  if (leaf_size < 1) return Status::InvalidArgument(fmt::format("leaf size must be >= 1 (got {})", leaf_size));
  const uint32_t n = uint32_t(boxes.size());
  Bvh bvh;
  bvh.order_.resize(n);
  std::iota(bvh.order_.begin(), bvh.order_.end(), 0u);
  Builder b{boxes, leaf_size, interrupter, {}, bvh.order_, {}};
  b.nodes.resize(std::max<size_t>(1, n));
  b.centroids.resize(n);
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, n, 16384), [&](const tbb::blocked_range<uint32_t>& r) {
    for (uint32_t i = r.begin(); i != r.end(); ++i)
      for (int a = 0; a < 3; ++a) b.centroids[i][a] = 0.5f * boxes[i].lo[a] + 0.5f * boxes[i].hi[a];
  });
  if (n <= uint32_t(leaf_size)) {  // the root is an inner node: one leaf of everything, one empty
    b.next_node = 1;
    b.setChildren(0, b.leaf(0, n), b.leaf(0, 0));
  } else {
    b.build(0, n, 0);
  }
  if (b.stopped || isInterrupted(interrupter)) return interruptedStatus(interrupter);
  b.nodes.resize(b.next_node.load());
  bvh.nodes_.reserve(b.nodes.size() / 2 + 1);
  bvh.nodes_.emplace_back();
  b.collapse(0, 0, bvh.nodes_);
  bvh.nodes_.shrink_to_fit();
  for (uint32_t i = 0; i < n; ++i) bvh.root_.add(boxes[i]);
  *out = std::move(bvh);
  return Status::Ok();
}

}  // namespace distband
