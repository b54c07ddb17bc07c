#include "core/band/internal/brick_table.h"

#include <algorithm>
#include <cstdlib>
#include <new>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/first_touch.h"

namespace distband::band_internal {

BrickState::BrickState(Coord o, bool with_lifespan) : origin(o) {
  for (int i = 0; i < kBrickVoxels; ++i) key[i].store(kUntouched, std::memory_order_relaxed);
  if (with_lifespan) {
    expiry = std::make_unique<std::atomic<uint16_t>[]>(kBrickVoxels);
    for (int i = 0; i < kBrickVoxels; ++i) expiry[i].store(kNeverExpires, std::memory_order_relaxed);
  }
}

namespace {
constexpr size_t kPooledBrickBytes =
    (sizeof(BrickState) + alignof(BrickState) - 1) / alignof(BrickState) * alignof(BrickState);
}  // namespace

BrickPool::ChunkHeader* BrickPool::chunkOf(void* p) {
  return reinterpret_cast<ChunkHeader*>(roundDownToHugePage(reinterpret_cast<uintptr_t>(p)));
}

void* BrickPool::allocate() {
  static_assert(kPooledBrickBytes >= sizeof(FreeBrick) && kHugePageBytes >= sizeof(ChunkHeader) + kPooledBrickBytes);
  std::lock_guard<std::mutex> lock(mutex_);
  void* p;
  if (FreeBrick* f = free_) {
    free_ = f->next;
    p = f;
  } else {
    if (size_t(end_ - next_) < kPooledBrickBytes) {
      auto* chunk = new (mapHugeAligned(kHugePageBytes)) ChunkHeader;
      chunks_.push_back(chunk);
      next_ = reinterpret_cast<char*>(chunk) + sizeof(ChunkHeader);
      end_ = reinterpret_cast<char*>(chunk) + kHugePageBytes;
    }
    p = next_;
    next_ += kPooledBrickBytes;
  }
  ++chunkOf(p)->live;
  return p;
}

void BrickPool::deallocate(void* p) {
  std::lock_guard<std::mutex> lock(mutex_);
  ChunkHeader* c = chunkOf(p);
  --c->live;
  if (!draining_)
    free_ = new (p) FreeBrick{free_};
  else if (c->live == 0)
    unmapLocked(c);
}

void BrickPool::unmapLocked(ChunkHeader* c) {
  if (end_ && reinterpret_cast<char*>(c) == end_ - kHugePageBytes) next_ = end_ = nullptr;
  const auto it = std::find(chunks_.begin(), chunks_.end(), c);
  *it = chunks_.back();
  chunks_.pop_back();
  unmapHugeAligned(c, kHugePageBytes);
}

void BrickPool::drain() {
  std::lock_guard<std::mutex> lock(mutex_);
  draining_ = true;
  free_ = nullptr;  // freed storage is not reused any more (it may lie in chunks about to be unmapped)
  for (size_t i = chunks_.size(); i-- > 0;)
    if (chunks_[i]->live == 0) unmapLocked(chunks_[i]);
}

void BrickPool::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  for (ChunkHeader* c : chunks_) unmapHugeAligned(c, kHugePageBytes);
  std::vector<ChunkHeader*>().swap(chunks_);
  free_ = nullptr;
  next_ = end_ = nullptr;
  draining_ = false;
}

namespace {
void* zeroed(size_t count, size_t size) {
  void* p = std::calloc(std::max<size_t>(count, 1), size);
  if (!p) throw std::bad_alloc();
  return p;
}
}  // namespace

BrickTable::BrickTable(Coord brick_dims, bool with_lifespan) : bdims_(brick_dims), with_lifespan_(with_lifespan) {
  auto up = [](int n) { return (n + kBlockSize - 1) >> kBlockLog2; };
  tdims_ = {up(bdims_.x), up(bdims_.y), up(bdims_.z)};
  top_size_ = size_t(tdims_.x) * tdims_.y * tdims_.z;
  // Ids are 32-bit and kNoBrick is the last one: at most 2^20 - 1 super-blocks (far more bricks than memory holds).
  max_blocks_ = std::min<size_t>(top_size_, (size_t(1) << (32 - 3 * kBlockLog2)) - 1);
  top_ = static_cast<Block**>(zeroed(top_size_, sizeof(Block*)));
  blocks_ = static_cast<Block**>(zeroed(max_blocks_, sizeof(Block*)));
}

BrickTable::~BrickTable() {
  releaseAll();
  const size_t n = blockCount();
  for (size_t i = 0; i < n; ++i) delete blocks_[i];
  std::free(blocks_);
  std::free(top_);
}

BrickTable::Block* BrickTable::createBlock(const Coord& bc) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::atomic_ref<Block*> cell(top_[topIndex(bc)]);
  if (Block* b = cell.load(std::memory_order_acquire)) return b;
  const size_t number = block_count_.load(std::memory_order_relaxed);
  if (number >= max_blocks_) throw std::runtime_error("distband engine: brick table full");
  auto* b = new Block;
  b->base = {bc.x & ~(kBlockSize - 1), bc.y & ~(kBlockSize - 1), bc.z & ~(kBlockSize - 1)};
  b->number = uint32_t(number);
  blocks_[number] = b;
  block_count_.store(number + 1, std::memory_order_release);
  cell.store(b, std::memory_order_release);
  return b;
}

size_t BrickTable::releaseAll() {
  std::atomic<size_t> freed{0};
  const size_t n = blockCount() * kBlockBricks;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
    size_t count = 0;
    for (size_t i = r.begin(); i != r.end(); ++i)
      if (BrickState* b = slot(uint32_t(i)).exchange(nullptr, std::memory_order_relaxed)) b->~BrickState(), ++count;
    freed += count;
  });
  pool_.reset();  // no brick is left: their storage goes at once
  return freed;
}

}  // namespace distband::band_internal
