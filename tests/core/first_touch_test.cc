// Tests for core/first_touch.h's fresh-storage helpers: huge-page advice stays inside the range it is given,
// mapHugeAligned's memory is 2 MiB-aligned and whole, ChunkArena's runs are disjoint and stay valid, and
// appendUnsetBricks leaves bricks the caller can fill.
#include "core/first_touch.h"

#include <cstdint>
#include <cstring>
#include <set>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

TEST(FirstTouch, MapHugeAlignedIsAlignedAndWritableToItsEnd) {
  for (size_t bytes : {size_t(1), size_t(3) << 20, kHugePageBytes}) {
    auto* p = static_cast<unsigned char*>(mapHugeAligned(bytes));
    EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % kHugePageBytes, 0u) << bytes;
    p[bytes - 1] = 2;
    p[0] = 1;
    EXPECT_EQ(p[bytes - 1], bytes == 1 ? 1 : 2);
    if (bytes > 1) p[(bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes - 1] = 3;  // the rounded end
    unmapHugeAligned(p, bytes);
  }
}

TEST(FirstTouch, AdviceOnAPartOfABufferLeavesItsContentsAlone) {
  // Advice covers only the whole 2 MiB pages inside the range; the bytes around and inside are unchanged.
  std::vector<unsigned char> buffer((size_t(5) << 20) + 123, 7);
  adviseHugePages(buffer.data() + 1, buffer.size() - 2);
  adviseHugePages(buffer.data(), 100);  // no whole page: nothing to advise
  for (size_t i = 0; i < buffer.size(); i += 4093) ASSERT_EQ(buffer[i], 7) << i;
}

TEST(FirstTouch, MappedAllocatorMapsLargeArraysAlignedAndKeepsSmallOnesOnTheHeap) {
  std::vector<uint32_t, MappedAllocator<uint32_t>> large(size_t(3) << 20 >> 2);
  std::vector<uint32_t, MappedAllocator<uint32_t>> small(100);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(large.data()) % kHugePageBytes, 0u);
  for (size_t i = 0; i < large.size(); ++i) large[i] = uint32_t(i);
  large.resize(large.size() * 2);  // regrows through the allocator: the old entries move along
  for (size_t i = 0; i < large.size() / 2; i += 4099) ASSERT_EQ(large[i], i);
  small.assign(100, 9);
  EXPECT_EQ(small[99], 9u);
}

TEST(FirstTouch, ChunkArenaRunsAreDisjointAndKeepTheirValues) {
  struct Item {
    uint32_t run, index;
  };
  ChunkArena<Item> arena;
  std::vector<std::pair<Item*, size_t>> runs;
  // More than one chunk's worth, with runs of every size up to 512 (a brick's voxels).
  size_t total = 0;
  for (uint32_t r = 0; total * sizeof(Item) < 3 * ChunkArena<Item>::kChunkBytes; ++r) {
    const size_t n = (r * 37) % 513;
    Item* p = arena.take(n);
    for (size_t i = 0; i < n; ++i) new (p + i) Item{r, uint32_t(i)};
    runs.emplace_back(p, n);
    total += n;
  }
  std::set<const Item*> seen;
  for (uint32_t r = 0; r < runs.size(); ++r) {
    const auto [p, n] = runs[r];
    for (size_t i = 0; i < n; ++i) {
      ASSERT_EQ(p[i].run, r);
      ASSERT_EQ(p[i].index, i);
      ASSERT_TRUE(seen.insert(p + i).second) << "run " << r << " overlaps an earlier one";
    }
  }
}

TEST(FirstTouch, AppendUnsetBricksAddsBricksToFill) {
  std::vector<Brick> out(3);
  appendUnsetBricks(out, 700);  // > 1 MiB: the pages are touched in parallel and advised
  ASSERT_EQ(out.size(), 703u);
  for (Brick& b : out) {
    b.values.fill(1.5f);
    b.mask.set(5);
  }
  EXPECT_EQ(out.back().values[511], 1.5f);
  EXPECT_EQ(out.back().mask.count(), 1);
}

}  // namespace
}  // namespace distband
