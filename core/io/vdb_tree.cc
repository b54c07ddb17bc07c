#include "core/io/vdb_tree.h"

#include <algorithm>
#include <bit>
#include <tuple>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include "core/first_touch.h"

namespace distband {
namespace {

// The first slab holds a few leaves (small fields stay small); later ones are one 2 MiB huge page each, mapped on
// their own (mapHugeAligned): a leaf's first touch was otherwise a 4 KiB page fault of its own (~30 % of the page
// faults of a 512^3 mesh run writing a .vdb, ~13 µs each on some virtual machines). They came from malloc as
// 2 MiB-aligned blocks before, whose split-off ends put headers in pages of their own: in the CLI's huge-page heap
// (client/batch_heap.h) each slab took a second huge page (a 512^3 teapot's 22 MiB of leaves raised RSS by 42 MiB).
constexpr size_t kFirstSlabLeaves = 256;

Coord alignDown(const Coord& c, int dim) { return {c.x & ~(dim - 1), c.y & ~(dim - 1), c.z & ~(dim - 1)}; }
bool lexLess(const Coord& a, const Coord& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); }
// Table offsets, x-major as in OpenVDB's nodes.
int offset2(const Coord& c) {
  return (((c.x & 4095) >> 7) << 10) | (((c.y & 4095) >> 7) << 5) | ((c.z & 4095) >> 7);
}
int offset1(const Coord& c) { return (((c.x & 127) >> 3) << 8) | (((c.y & 127) >> 3) << 4) | ((c.z & 127) >> 3); }

template <size_t kWords>
void setBit(std::array<uint64_t, kWords>& words, int i) {
  words[size_t(i) >> 6] |= uint64_t(1) << (i & 63);
}

template <size_t kWords>
void computeRank(const std::array<uint64_t, kWords>& child, std::array<uint32_t, kWords>& rank) {
  uint32_t n = 0;
  for (size_t w = 0; w < kWords; ++w) {
    rank[w] = n;
    n += uint32_t(std::popcount(child[w]));
  }
}

// OpenVDB's signed flood fill rule over one node's (2^kLog2)^3 entries, in x-major order: an entry that is not set
// (`isSet`) takes the sign of the last set entry met before it on its z scanline, a scanline's start that of its y
// row's last set entry, a row's start that of its x plane's, and everything before the first set entry the sign
// `first_inside`. `insideOf(i)` is the sign a set entry passes on (its own value, or a child's last value);
// `fill(i, inside)` gives an unset entry its sign.
template <int kLog2, class IsSet, class InsideOf, class Fill>
void scanlineSignFill(bool first_inside, IsSet isSet, InsideOf insideOf, Fill fill) {
  constexpr int kDim = 1 << kLog2;
  bool x_inside = first_inside;
  for (int x = 0; x < kDim; ++x) {
    const int x00 = x << (2 * kLog2);
    if (isSet(x00)) x_inside = insideOf(x00);
    bool y_inside = x_inside;
    for (int y = 0; y < kDim; ++y) {
      const int xy0 = x00 + (y << kLog2);
      if (isSet(xy0)) y_inside = insideOf(xy0);
      bool z_inside = y_inside;
      for (int z = 0; z < kDim; ++z) {
        const int xyz = xy0 + z;
        if (isSet(xyz)) z_inside = insideOf(xyz);
        else fill(xyz, z_inside);
      }
    }
  }
}

// The index of the first set bit of `words`, or -1.
template <size_t kWords>
int firstBit(const std::array<uint64_t, kWords>& words) {
  for (size_t w = 0; w < kWords; ++w)
    if (words[w]) return int(w * 64) + std::countr_zero(words[w]);
  return -1;
}

// An internal node's tiles: children pass on their last value, the first child's first value starts the walk.
template <int kLog2, class TableT, class FirstOf, class LastOf>
void fillTable(TableT& t, FirstOf firstOf, LastOf lastOf) {
  const int first = firstBit(t.child);
  if (first < 0) return;  // nodes exist only with children
  t.negative.fill(0);
  scanlineSignFill<kLog2>(
      firstOf(first) < 0, [&](int i) { return t.isChild(i); }, [&](int i) { return lastOf(i) < 0; },
      [&](int i, bool inside) {
        if (inside) setBit(t.negative, i);
      });
}

}  // namespace

template <class T>
template <int kWords>
uint32_t VdbTree<T>::Table<kWords>::childIndex(int i) const {
  const size_t w = size_t(i) >> 6;
  return first + rank[w] + uint32_t(std::popcount(child[w] & ((uint64_t(1) << (i & 63)) - 1)));
}

template <class T>
VdbTree<T>::VdbTree(T background) : background_(background) {}

template <class T>
VdbTree<T>::~VdbTree() = default;

template <class T>
typename VdbTree<T>::Leaf* VdbTree<T>::touchLeaf(const Coord& origin) {
  bool created = false;
  Leaf* leaf = touchLeaf(origin, &created);
  if (created) initLeaf(leaf, origin);
  return leaf;
}

template <class T>
void VdbTree<T>::initLeaf(Leaf* leaf, const Coord& origin) const {
  ::new (static_cast<void*>(leaf)) Leaf{origin, BrickMask{}, {}};
  leaf->values.fill(background_);
}

template <class T>
typename VdbTree<T>::Leaf* VdbTree<T>::touchLeaf(const Coord& origin, bool* created) {
  static_assert(std::is_trivially_destructible_v<Leaf>, "slabs are freed without destroying their leaves");
  auto [it, inserted] = index_.try_emplace(origin, nullptr);
  *created = inserted;
  if (!inserted) return it->second;
  if (slabs_.empty() || slab_used_ == slab_size_) {
    // Raw storage: each leaf is made by initLeaf, on whichever thread fills it.
    static_assert(kHugePageBytes % alignof(Leaf) == 0);
    const bool first = slabs_.empty();
    slab_size_ = first ? kFirstSlabLeaves : kHugePageBytes / sizeof(Leaf);
    if (first)
      slabs_.emplace_back(static_cast<Leaf*>(::operator new(slab_size_ * sizeof(Leaf))), SlabDelete{false});
    else
      slabs_.emplace_back(static_cast<Leaf*>(mapHugeAligned(kHugePageBytes)), SlabDelete{true});
    slab_used_ = 0;
  }
  Leaf* leaf = slabs_.back().get() + slab_used_++;
  leaves_.push_back(leaf);
  it->second = leaf;
  return leaf;
}

template <class T>
void VdbTree<T>::seal() {
  if (sealed_) return;
  sealed_ = true;
  std::unordered_map<Coord, Leaf*, CoordHash>().swap(index_);
  // Tree order: root children by origin, then the 4096³ node's table offset, then the 128³ node's.
  struct Keyed {
    Coord node2;
    uint32_t offsets;
    Leaf* leaf;
  };
  std::vector<Keyed> keyed(leaves_.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves_.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const Coord o = leaves_[i]->origin;
      keyed[i] = {alignDown(o, kNode2Dim), uint32_t(offset2(o)) << 12 | uint32_t(offset1(o)), leaves_[i]};
    }
  });
  tbb::parallel_sort(keyed.begin(), keyed.end(), [](const Keyed& a, const Keyed& b) {
    return std::tie(a.node2.x, a.node2.y, a.node2.z, a.offsets) < std::tie(b.node2.x, b.node2.y, b.node2.z, b.offsets);
  });
  for (size_t i = 0; i < keyed.size(); ++i) {
    const Keyed& k = keyed[i];
    leaves_[i] = k.leaf;
    const Coord o1 = alignDown(k.leaf->origin, kNode1Dim);
    if (nodes2_.empty() || !(nodes2_.back().origin == k.node2)) {
      nodes2_.emplace_back();
      nodes2_.back().origin = k.node2;
      nodes2_.back().first = uint32_t(nodes1_.size());
    }
    if (nodes1_.empty() || !(nodes1_.back().origin == o1)) {
      nodes1_.emplace_back();
      nodes1_.back().origin = o1;
      nodes1_.back().first = uint32_t(i);
      setBit(nodes2_.back().child, offset2(o1));
    }
    setBit(nodes1_.back().child, offset1(k.leaf->origin));
  }
  for (Node1& n : nodes1_) computeRank(n.child, n.rank);
  for (Node2& n : nodes2_) computeRank(n.child, n.rank);
}

template <class T>
T VdbTree<T>::firstValue1(const Node1& n) const {
  return n.isChild(0) ? leaves_[n.childIndex(0)]->values[0] : tileValue(n.isNegative(0));
}
template <class T>
T VdbTree<T>::lastValue1(const Node1& n) const {
  constexpr int kLast = kNode1Size - 1;
  return n.isChild(kLast) ? leaves_[n.childIndex(kLast)]->values[kBrickVoxels - 1] : tileValue(n.isNegative(kLast));
}
template <class T>
T VdbTree<T>::firstValue2(const Node2& n) const {
  return n.isChild(0) ? firstValue1(nodes1_[n.childIndex(0)]) : tileValue(n.isNegative(0));
}
template <class T>
T VdbTree<T>::lastValue2(const Node2& n) const {
  constexpr int kLast = kNode2Size - 1;
  return n.isChild(kLast) ? lastValue1(nodes1_[n.childIndex(kLast)]) : tileValue(n.isNegative(kLast));
}

template <class T>
void VdbTree<T>::signedFloodFill() {
  seal();
  const T outside = background_ < 0 ? T(-background_) : background_, inside = T(-outside);
  // Bottom-up, as OpenVDB's NodeManager does it: leaves, then 128³ nodes, then 4096³ nodes, then the root.
  tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves_.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      Leaf& leaf = *leaves_[i];
      T* v = leaf.values.data();
      const int first = firstBit(leaf.mask.words);
      if (first < 0) {
        leaf.values.fill(v[0] < 0 ? inside : outside);
        continue;
      }
      scanlineSignFill<kLeafLog2>(
          v[first] < 0, [&](int i) { return leaf.mask.test(i); }, [&](int i) { return v[i] < 0; },
          [&](int i, bool in) { v[i] = in ? inside : outside; });
    }
  });
  // Tiles are read as +/-background through tileValue(): the flood fill's values, with the outside one positive.
  background_ = outside;
  tbb::parallel_for(size_t(0), nodes1_.size(), [&](size_t i) {
    Node1& n = nodes1_[i];
    fillTable<kNode1Log2>(
        n, [&](int e) { return leaves_[n.childIndex(e)]->values[0]; },
        [&](int e) { return leaves_[n.childIndex(e)]->values[kBrickVoxels - 1]; });
  });
  tbb::parallel_for(size_t(0), nodes2_.size(), [&](size_t i) {
    Node2& n = nodes2_[i];
    fillTable<kNode2Log2>(
        n, [&](int e) { return firstValue1(nodes1_[n.childIndex(e)]); },
        [&](int e) { return lastValue1(nodes1_[n.childIndex(e)]); });
  });
  // Root: inside tiles fill the gaps of a z-run of children whose facing values are both inside.
  root_tiles_.clear();
  for (size_t i = 0; i + 1 < nodes2_.size(); ++i) {
    const Node2 &a = nodes2_[i], &b = nodes2_[i + 1];
    if (a.origin.x != b.origin.x || a.origin.y != b.origin.y || b.origin.z - a.origin.z == kNode2Dim) continue;
    if (!(lastValue2(a) < 0) || !(firstValue2(b) < 0)) continue;
    for (int z = a.origin.z + kNode2Dim; z != b.origin.z; z += kNode2Dim) root_tiles_.push_back({{a.origin.x, a.origin.y, z}, true});
  }
}

template <class T>
const typename VdbTree<T>::Node2* VdbTree<T>::findNode2(const Coord& origin) const {
  auto it = std::lower_bound(nodes2_.begin(), nodes2_.end(), origin,
                             [](const Node2& n, const Coord& o) { return lexLess(n.origin, o); });
  return it != nodes2_.end() && it->origin == origin ? &*it : nullptr;
}

template <class T>
T VdbTree<T>::value(const Coord& c) const {
  const Coord o2 = alignDown(c, kNode2Dim);
  const Node2* n2 = findNode2(o2);
  if (!n2) {
    auto it = std::lower_bound(root_tiles_.begin(), root_tiles_.end(), o2,
                               [](const RootTile& t, const Coord& o) { return lexLess(t.origin, o); });
    return it != root_tiles_.end() && it->origin == o2 ? tileValue(it->negative) : background_;
  }
  const int e2 = offset2(c);
  if (!n2->isChild(e2)) return tileValue(n2->isNegative(e2));
  const Node1& n1 = nodes1_[n2->childIndex(e2)];
  const int e1 = offset1(c);
  if (!n1.isChild(e1)) return tileValue(n1.isNegative(e1));
  return leaves_[n1.childIndex(e1)]->values[size_t(brickOffset(c.x & 7, c.y & 7, c.z & 7))];
}

template <class T>
int64_t VdbTree<T>::leafIndex(const Coord& c) const {
  const Node2* n2 = findNode2(alignDown(c, kNode2Dim));
  if (!n2 || !n2->isChild(offset2(c))) return -1;
  const Node1& n1 = nodes1_[n2->childIndex(offset2(c))];
  return n1.isChild(offset1(c)) ? int64_t(n1.childIndex(offset1(c))) : -1;
}

template <class T>
int64_t VdbTree<T>::activeVoxels() const {
  int64_t n = 0;
  for (const Leaf* l : leaves_) n += l->mask.count();
  return n;
}

template <class T>
bool VdbTree<T>::activeBounds(Coord* min, Coord* max) const {
  // Per leaf from its mask words: offset (x << 6) | (y << 3) | z, so word w is the plane x = w with bits (y << 3) | z,
  // and OR-ing the words gives the (y, z) footprint of the leaf.
  bool any = false;
  for (const Leaf* l : leaves_) {
    uint64_t yz = 0;
    int x0 = 8, x1 = -1;
    for (int w = 0; w < 8; ++w)
      if (l->mask.words[size_t(w)]) yz |= l->mask.words[size_t(w)], x0 = std::min(x0, w), x1 = w;
    if (!yz) continue;
    uint8_t ys = 0, zs = 0;
    for (int y = 0; y < 8; ++y) {
      const uint8_t row = uint8_t(yz >> (8 * y));
      if (row) ys |= uint8_t(1 << y), zs |= row;
    }
    const Coord lo = l->origin + Coord{x0, std::countr_zero(ys), std::countr_zero(zs)};
    const Coord hi = l->origin + Coord{x1, 7 - std::countl_zero(ys), 7 - std::countl_zero(zs)};
    if (!any) *min = lo, *max = hi, any = true;
    min->x = std::min(min->x, lo.x), min->y = std::min(min->y, lo.y), min->z = std::min(min->z, lo.z);
    max->x = std::max(max->x, hi.x), max->y = std::max(max->y, hi.y), max->z = std::max(max->z, hi.z);
  }
  return any;
}

template class VdbTree<float>;
template class VdbTree<int32_t>;
template class VdbTree<int64_t>;

}  // namespace distband
