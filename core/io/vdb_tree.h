// VdbTree<T>: a sparse grid of 8³ leaves in OpenVDB's tree shape — a root over 4096³ nodes (32³ tables) over 128³
// nodes (16³ tables) over 8³ leaves, OpenVDB's "Tree_<type>_5_4_3" — built from delivered bricks, so that .vdb files
// can be written (core/io/vdb_file.h) and a finished field read back (slices, isosurfaces) without linking OpenVDB:
// loading libopenvdb alone costs a process ~30 ms of dynamic linking, as much as the rest of a 256³ narrow-band job.
// Contract:
//   * Building: touchLeaf(origin) creates (or finds) the leaf at an 8-aligned origin, its values set to the
//     background and no voxel active; the caller writes values and sets mask bits (Leaf::mask = active voxels). Leaf
//     creation is single-threaded; filling distinct leaves from several threads is safe. touchLeaf(origin, &created)
//     leaves a new leaf's storage untouched, for the caller to initLeaf() on its own thread (so creating many leaves
//     at once is not a serial pass over their 2 KiB each, nor over their pages' first-touch faults); until then the
//     leaf must not be read.
//   * seal() ends building: leaves are put in OpenVDB's tree order (root children by origin, then table offsets;
//     the order the file format needs) and the internal nodes' tables are made; afterwards no leaf may be added,
//     leaves() is in tree order and value() answers. Every internal-node and root tile is inactive.
//   * signedFloodFill() (float trees, after seal) gives every inactive value OpenVDB's tools::signedFloodFill result:
//     inactive voxels of a leaf take the sign of the nearest active voxel before them on their z scanline (x-major
//     order), tiles the sign of the neighbouring child before them, root tiles of -background fill z-runs between
//     inside children; the background becomes +|background|. So a reader gets +background outside and -background
//     inside anywhere the band was not delivered, exactly as from a tree OpenVDB flood-filled itself.
//   * value(c): the value at any voxel (active, inactive, tile or background).
// Not thread-safe while building; const methods are safe to call concurrently after seal().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <new>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "core/brick.h"
#include "core/first_touch.h"
#include "core/types.h"

namespace distband {

template <class T>
class VdbTree {
 public:
  static constexpr int kLeafLog2 = 3, kNode1Log2 = 4, kNode2Log2 = 5;                  // table sizes: 8, 16, 32
  static constexpr int kLeafDim = 8, kNode1Dim = 128, kNode2Dim = 4096;                // index-space widths
  static constexpr int kNode1Size = 1 << (3 * kNode1Log2), kNode2Size = 1 << (3 * kNode2Log2);  // table entries

  struct Leaf {
    Coord origin;
    BrickMask mask;                         ///< active voxels (brick order = OpenVDB's leaf order, z fastest)
    std::array<T, kBrickVoxels> values;
  };
  /// A node's table: which entries are children, and which tiles hold -background (the rest hold background).
  template <int kWords>
  struct Table {
    std::array<uint64_t, kWords> child{}, negative{};
    std::array<uint32_t, kWords> rank{};  ///< children in the words before each word
    uint32_t first = 0;                   ///< index of the node's first child (leaves or level-1 nodes)
    Coord origin;
    bool isChild(int i) const { return (child[size_t(i) >> 6] >> (i & 63)) & 1; }
    bool isNegative(int i) const { return (negative[size_t(i) >> 6] >> (i & 63)) & 1; }
    uint32_t childIndex(int i) const;  ///< for isChild(i)
  };
  using Node1 = Table<kNode1Size / 64>;  ///< 128³: 16³ entries, children are leaves
  using Node2 = Table<kNode2Size / 64>;  ///< 4096³: 32³ entries, children are level-1 nodes
  struct RootTile {
    Coord origin;  ///< of a 4096³ region without a child
    bool negative;
  };

  explicit VdbTree(T background);
  ~VdbTree();
  VdbTree(const VdbTree&) = delete;
  VdbTree& operator=(const VdbTree&) = delete;

  Leaf* touchLeaf(const Coord& origin);
  Leaf* touchLeaf(const Coord& origin, bool* created);
  /// Makes a leaf from touchLeaf(origin, &created) with created = true: background values, nothing active.
  void initLeaf(Leaf* leaf, const Coord& origin) const;
  void seal();
  void signedFloodFill();
  bool sealed() const { return sealed_; }

  T background() const { return background_; }
  T value(const Coord& c) const;
  /// The position in leaves() of the leaf holding voxel c, or -1 (after seal()).
  int64_t leafIndex(const Coord& c) const;
  const std::vector<Leaf*>& leaves() const { return leaves_; }
  const std::vector<Node1>& nodes1() const { return nodes1_; }
  const std::vector<Node2>& nodes2() const { return nodes2_; }  ///< sorted by origin (x, then y, then z)
  const std::vector<RootTile>& rootTiles() const { return root_tiles_; }  ///< sorted by origin
  int64_t activeVoxels() const;
  /// Bounding box of the active voxels; false when there are none.
  bool activeBounds(Coord* min, Coord* max) const;

  /// T of an entry `i` of a table: the child's first / last value, or the tile's.
  T tileValue(bool negative) const { return negative ? T(-background_) : background_; }

 private:
  T firstValue1(const Node1& n) const;
  T lastValue1(const Node1& n) const;
  T firstValue2(const Node2& n) const;
  T lastValue2(const Node2& n) const;
  const Node2* findNode2(const Coord& origin) const;

  T background_;
  bool sealed_ = false;
  // A slab: the first, small one from the heap; the others one 2 MiB huge page each, mapped on their own.
  struct SlabDelete {
    bool mapped = false;
    void operator()(Leaf* p) const {
      if (mapped)
        unmapHugeAligned(p, kHugePageBytes);
      else
        ::operator delete(p);
    }
  };
  std::vector<std::unique_ptr<Leaf, SlabDelete>> slabs_;  // leaves, allocated in slabs of raw storage
  size_t slab_used_ = 0;
  size_t slab_size_ = 0;  // leaves the newest slab holds
  std::vector<Leaf*> leaves_;
  std::unordered_map<Coord, Leaf*, CoordHash> index_;
  std::vector<Node1> nodes1_;
  std::vector<Node2> nodes2_;
  std::vector<RootTile> root_tiles_;
};

extern template class VdbTree<float>;
extern template class VdbTree<int32_t>;
extern template class VdbTree<int64_t>;

}  // namespace distband
