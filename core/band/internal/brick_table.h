// BrickTable: the engine's sparse storage of 8^3 bricks of voxel state, and the map from brick coordinates to them.
// Contract:
//   * A brick is named by a 32-bit id that is stable for the run. The coordinate -> id map is two-level: a top level
//     over super-blocks of 16^3 bricks (a lazily zeroed array, 8 bytes per 128^3 voxels of the grid) and, per touched
//     super-block, 4096 brick slots (32 KiB). Ids are (super-block number << 12 | brick within it), super-blocks
//     numbered in creation order, so ids say nothing about position: order bricks by originKey().
//   * Memory follows the touched bricks: a 16384^3 grid costs 24 MiB of address space (the top level and the
//     super-block directory, both lazily zeroed) and, per touched super-block, its 32 KiB of slots and at most a page
//     of each array. The propagation creates the super-blocks of the neighbouring bricks it looks at (idOf with
//     create), so a band along a super-block face may touch the one beyond it without a brick there.
//   * Lookups (find, brickAt, bricksFrom, idAt, get, slot) are lock-free loads. idOf(..., create), neighbourId,
//     neighbourSlot and getOrCreate() may be called from any number of threads: a super-block is created under a
//     mutex (once per 128^3 voxels), a brick by CAS, so concurrent creators of one brick all get the same one.
//     release() and releaseAll() must not race with users of the bricks they free.
//   * Bricks live in 2 MiB chunks advised to use transparent huge pages (BrickPool): a brick's first touch was a 4 KiB
//     page fault of its own, ~15 % of a thin mesh band's engine time on a virtual machine whose faults cost ~13 µs.
// Used by every part of the engine (core/band/internal/).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <vector>

#include "core/band/internal/band_key.h"
#include "core/grid.h"
#include "core/types.h"

namespace distband::band_internal {

inline constexpr uint16_t kNeverExpires = 0xFFFF;

// 8 bytes and 5 bits a voxel (2 bytes more with a lifespan): memory follows the touched bricks.
struct BrickState {
  BrickState(Coord o, bool with_lifespan);
  Coord origin;
  std::atomic<bool> pending{false};  // listed for emission (holds touched, not yet emitted voxels)
  std::atomic<uint64_t> key[kBrickVoxels];
  VoxelBits listed;   // already in the next front
  VoxelBits emitted;  // delivered (final)
  VoxelBits dirty;    // changed since the last correction round (listed in ThreadBuffers::dirty)
  VoxelBits queued;   // already a candidate of the current correction round
  // A band voxel of a Seeds::band_exact band (set before the first step, then only read). One cache line, tested
  // before the voxel's key is loaded.
  VoxelBits exact;
  std::unique_ptr<std::atomic<uint16_t>[]> expiry;  // paper mode: last step in which a voxel accepts offers
  uint32_t scan_site = 0;  // second ring's scan: the one site all touched voxels hold (see scanAndCheck)
};

// Storage for bricks: 2 MiB chunks (each one huge page where the system has them), mapped on their own and carved in
// order; a freed brick's storage is reused by the next one made. Once draining (no brick will be made any more: the
// last segment's emission), a chunk is unmapped as soon as its last brick is freed, so the memory goes back while
// the output grows. reset() unmaps every chunk. Thread-safe.
class BrickPool {
 public:
  BrickPool() = default;
  ~BrickPool() { reset(); }
  BrickPool(const BrickPool&) = delete;
  BrickPool& operator=(const BrickPool&) = delete;
  void* allocate();
  void deallocate(void* p);
  /// From now on nothing is allocated: emptied chunks are unmapped (those empty now at once).
  void drain();
  /// Unmaps every chunk: no brick may live in them any more.
  void reset();

 private:
  struct FreeBrick {
    FreeBrick* next;
  };
  // At the start of each chunk (2 MiB-aligned: a brick's chunk is its address rounded down).
  struct alignas(64) ChunkHeader {
    uint32_t live = 0;  // bricks allocated in the chunk and not freed
  };
  static ChunkHeader* chunkOf(void* p);
  void unmapLocked(ChunkHeader* c);
  std::mutex mutex_;
  std::vector<ChunkHeader*> chunks_;
  FreeBrick* free_ = nullptr;
  char* next_ = nullptr;  // the unused rest of the newest chunk
  char* end_ = nullptr;
  bool draining_ = false;
};

class BrickTable {
 public:
  static constexpr int kBlockLog2 = 4;  // super-blocks of 16^3 bricks
  static constexpr int kBlockSize = 1 << kBlockLog2;
  static constexpr int kBlockBricks = kBlockSize * kBlockSize * kBlockSize;
  static constexpr uint32_t kNoBrick = ~uint32_t(0);  // outside the grid (or no super-block yet)

  /// `brick_dims`: bricks along each axis (Grid::brickDims()); each at most 2048 (kMaxGridDim / 8).
  BrickTable(Coord brick_dims, bool with_lifespan);
  ~BrickTable();
  BrickTable(const BrickTable&) = delete;
  BrickTable& operator=(const BrickTable&) = delete;

  const Coord& brickDims() const { return bdims_; }
  bool containsBrick(const Coord& bc) const {
    return bc.x >= 0 && bc.y >= 0 && bc.z >= 0 && bc.x < bdims_.x && bc.y < bdims_.y && bc.z < bdims_.z;
  }

  /// The id of the brick at brick coordinate `bc`, kNoBrick outside the grid. Without `create`, also kNoBrick when
  /// its super-block does not exist (then neither does the brick); with it, the super-block is created.
  uint32_t idOf(const Coord& bc, bool create) {
    if (!containsBrick(bc)) return kNoBrick;
    Block* b = blockAt(bc);
    if (!b) {
      if (!create) return kNoBrick;
      b = createBlock(bc);
    }
    return (b->number << (3 * kBlockLog2)) | localIndex(bc);
  }
  uint32_t idAt(const Coord& bc) const {
    if (!containsBrick(bc)) return kNoBrick;
    const Block* b = blockAt(bc);
    return b ? (b->number << (3 * kBlockLog2)) | localIndex(bc) : kNoBrick;
  }
  /// The id of the brick `d` bricks away from brick `id` (at brick coordinate `bc`), creating its super-block.
  /// Neighbours in the same super-block (15 of 16 per axis) cost no map lookup.
  uint32_t neighbourId(uint32_t id, const Coord& bc, int dx, int dy, int dz) {
    const Coord n{bc.x + dx, bc.y + dy, bc.z + dz};
    if (!containsBrick(n)) return kNoBrick;  // super-blocks at the far faces reach past the grid
    const int lx = (bc.x & (kBlockSize - 1)) + dx, ly = (bc.y & (kBlockSize - 1)) + dy,
              lz = (bc.z & (kBlockSize - 1)) + dz;
    if (uint32_t(lx) < uint32_t(kBlockSize) && uint32_t(ly) < uint32_t(kBlockSize) &&
        uint32_t(lz) < uint32_t(kBlockSize))
      return uint32_t(int(id) + ((dz << kBlockLog2) + dy) * kBlockSize + dx);
    return idOf(n, true);
  }

  /// neighbourId for the propagation's hot path: also the neighbour's slot (null outside the grid), found from the
  /// slot `from` of brick `id` when both share a super-block (their slots are contiguous there).
  std::atomic<BrickState*>* neighbourSlot(uint32_t id, std::atomic<BrickState*>* from, const Coord& bc, int dx, int dy,
                                          int dz, uint32_t* neighbour_id) {
    const int lx = (bc.x & (kBlockSize - 1)) + dx, ly = (bc.y & (kBlockSize - 1)) + dy,
              lz = (bc.z & (kBlockSize - 1)) + dz;
    if (uint32_t(lx) < uint32_t(kBlockSize) && uint32_t(ly) < uint32_t(kBlockSize) &&
        uint32_t(lz) < uint32_t(kBlockSize)) {
      // Not below the grid (the super-block starts inside it), but maybe past its far faces.
      if (bc.x + dx >= bdims_.x || bc.y + dy >= bdims_.y || bc.z + dz >= bdims_.z) {
        *neighbour_id = kNoBrick;
        return nullptr;
      }
      const int delta = ((dz << kBlockLog2) + dy) * kBlockSize + dx;
      *neighbour_id = uint32_t(int(id) + delta);
      return from + delta;
    }
    *neighbour_id = idOf({bc.x + dx, bc.y + dy, bc.z + dz}, true);
    return *neighbour_id == kNoBrick ? nullptr : &slot(*neighbour_id);
  }

  /// The slot holding brick `id` (null until created). `id` must come from idOf / idAt / neighbourId.
  std::atomic<BrickState*>& slot(uint32_t id) const {
    return blocks_[id >> (3 * kBlockLog2)]->slots[id & (kBlockBricks - 1)];
  }
  BrickState* get(uint32_t id, std::memory_order order = std::memory_order_relaxed) const {
    return slot(id).load(order);
  }
  /// The brick at brick coordinate `bc`, null outside the grid or untouched.
  BrickState* brickAt(const Coord& bc) const {
    if (!containsBrick(bc)) return nullptr;
    const Block* b = blockAt(bc);
    return b ? b->slots[localIndex(bc)].load(std::memory_order_relaxed) : nullptr;
  }
  /// The 2x2x2 bricks from brick coordinate `b0` on: bricks[(z << 2) | (y << 1) | x] is the one at b0 + (x, y, z)
  /// (null outside the grid or untouched), and (if `ids` is given) its id (kNoBrick without one). One map lookup
  /// when all eight share a super-block (most of the time), else one each.
  void bricksFrom(const Coord& b0, BrickState* bricks[8], uint32_t ids[8]) const {
    constexpr int m = kBlockSize - 1;
    if (b0.x >= 0 && b0.y >= 0 && b0.z >= 0 && (b0.x & m) < m && (b0.y & m) < m && (b0.z & m) < m &&
        b0.x + 1 < bdims_.x && b0.y + 1 < bdims_.y && b0.z + 1 < bdims_.z) {
      const Block* block = blockAt(b0);
      const uint32_t first = localIndex(b0);
      for (int j = 0; j < 8; ++j) {
        const uint32_t local = first + uint32_t((((j >> 2) << kBlockLog2) + ((j >> 1) & 1)) * kBlockSize + (j & 1));
        bricks[j] = block ? block->slots[local].load(std::memory_order_relaxed) : nullptr;
        if (ids) ids[j] = block ? (block->number << (3 * kBlockLog2)) | local : kNoBrick;
      }
      return;
    }
    for (int j = 0; j < 8; ++j) {
      const uint32_t id = idAt({b0.x + (j & 1), b0.y + ((j >> 1) & 1), b0.z + (j >> 2)});
      bricks[j] = id == kNoBrick ? nullptr : get(id);
      if (ids) ids[j] = id;
    }
  }
  /// The brick holding voxel `c` (inside the grid), null if untouched.
  BrickState* find(const Coord& c) const { return brickAt({c.x >> kBrickLog2, c.y >> kBrickLog2, c.z >> kBrickLog2}); }

  /// Brick `id`, created (all voxels untouched) if it does not exist yet; `*created` counts the bricks this call made.
  BrickState* getOrCreate(uint32_t id, int64_t* created) {
    std::atomic<BrickState*>& s = slot(id);
    BrickState* b = s.load(std::memory_order_acquire);
    if (b) return b;
    auto* fresh = new (pool_.allocate()) BrickState(originOf(id), with_lifespan_);
    if (s.compare_exchange_strong(b, fresh, std::memory_order_acq_rel)) {
      ++*created;
      return fresh;
    }
    destroy(fresh);
    return b;
  }

  /// Voxel coordinate of brick `id`'s origin.
  Coord originOf(uint32_t id) const {
    const Coord& base = blocks_[id >> (3 * kBlockLog2)]->base;
    const int local = int(id & (kBlockBricks - 1));
    return {(base.x + (local & (kBlockSize - 1))) << kBrickLog2,
            (base.y + ((local >> kBlockLog2) & (kBlockSize - 1))) << kBrickLog2,
            (base.z + (local >> (2 * kBlockLog2))) << kBrickLog2};
  }
  /// A key whose integer order is the (z, y, x) order of brick origins.
  static uint64_t originKey(const Coord& origin) {
    return (uint64_t(origin.z) << 42) | (uint64_t(origin.y) << 21) | uint64_t(origin.x);
  }

  /// Frees brick `id` (no-op if absent). Its slot reads null afterwards.
  void release(uint32_t id) {
    if (BrickState* b = slot(id).exchange(nullptr, std::memory_order_relaxed)) destroy(b);
  }
  /// Frees every brick (in parallel); returns how many there were. Super-blocks stay until destruction.
  size_t releaseAll();
  /// No brick will be created any more: the storage of released bricks goes back to the system as it empties.
  void drain() { pool_.drain(); }

  /// Super-blocks created so far, and the bytes the map itself holds at most (their slots, and a page of the top
  /// level and of the directory for each).
  size_t blockCount() const { return block_count_.load(std::memory_order_acquire); }
  size_t mapBytes() const { return blockCount() * (sizeof(Block) + 2 * 4096); }

 private:
  struct Block {
    std::atomic<BrickState*> slots[kBlockBricks] = {};
    Coord base;       // brick coordinate of slot 0
    uint32_t number;  // creation order; the high bits of its bricks' ids
  };
  static uint32_t localIndex(const Coord& bc) {
    constexpr int m = kBlockSize - 1;
    return uint32_t((((bc.z & m) << kBlockLog2) | (bc.y & m)) << kBlockLog2 | (bc.x & m));
  }
  size_t topIndex(const Coord& bc) const {
    return (size_t(bc.z >> kBlockLog2) * tdims_.y + size_t(bc.y >> kBlockLog2)) * tdims_.x + size_t(bc.x >> kBlockLog2);
  }
  Block* blockAt(const Coord& bc) const {
    return std::atomic_ref<Block*>(top_[topIndex(bc)]).load(std::memory_order_acquire);
  }
  Block* createBlock(const Coord& bc);
  void destroy(BrickState* b) {
    b->~BrickState();
    pool_.deallocate(b);
  }

  Coord bdims_, tdims_;
  bool with_lifespan_;
  size_t top_size_;
  size_t max_blocks_;
  // Both arrays come from calloc: untouched pages are never made resident. top_ is read through std::atomic_ref.
  Block** top_;     // super-block at each top-level cell, or null
  Block** blocks_;  // super-blocks by number (written under mutex_ before the top-level cell publishes them)
  std::atomic<size_t> block_count_{0};
  std::mutex mutex_;
  BrickPool pool_;
};

}  // namespace distband::band_internal
