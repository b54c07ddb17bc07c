// Tests for client/batch_heap: after configureBatchHeap() the heap's kept step is advised to use huge pages (the
// kernel's own mapping flags say so), blocks below 32 MiB come from it, larger ones than its free top holds are mapped
// on their own. Each test runs in its own process (gtest_discover_tests), so the policy applies to nothing else.
#include "client/batch_heap.h"

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer) || __has_feature(thread_sanitizer)
#define DISTBAND_TEST_SANITIZED_MALLOC 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DISTBAND_TEST_SANITIZED_MALLOC 1
#endif

namespace distband {
namespace {

bool kernelHasHugePages() { return std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled").good(); }

// The VmFlags line of the mapping of /proc/self/smaps that holds `p`, or "" when none does.
std::string vmFlagsAt(const void* p) {
  const auto at = reinterpret_cast<uintptr_t>(p);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    unsigned long lo = 0, hi = 0;
    if (std::sscanf(line.c_str(), "%lx-%lx ", &lo, &hi) == 2) {  // a mapping's first line; its fields follow
      inside = lo <= at && at < hi;
      continue;
    }
    if (inside && line.rfind("VmFlags:", 0) == 0) return line;
  }
  return "";
}

bool hasFlag(const std::string& flags, const std::string& flag) {
  std::istringstream words(flags);
  std::string w;
  while (words >> w)
    if (w == flag) return true;
  return false;
}

TEST(BatchHeap, AdvisesTheHeapsStepForHugePages) {
  const BatchHeap heap = configureBatchHeap();
#ifdef DISTBAND_TEST_SANITIZED_MALLOC
  EXPECT_EQ(heap.advised_bytes, 0u) << "a sanitizer's malloc does not grow the program break";
  GTEST_SKIP() << "malloc is the sanitizer's";
#endif
  if (!kernelHasHugePages()) GTEST_SKIP() << "the kernel has no transparent huge pages";
  // The 64 MiB step less its unaligned ends.
  EXPECT_GE(heap.advised_bytes, size_t(60) << 20);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(heap.advised_begin) % (size_t(2) << 20), 0u);
  const std::string flags = vmFlagsAt(heap.advised_begin);
  ASSERT_FALSE(flags.empty()) << "no mapping holds the advised range";
  EXPECT_TRUE(hasFlag(flags, "hg")) << flags;
  // Its last byte too: one mapping (the break's heap) holds the whole range.
  EXPECT_TRUE(hasFlag(vmFlagsAt(static_cast<const char*>(heap.advised_begin) + heap.advised_bytes - 1), "hg"));
}

// Blocks below 32 MiB come from the break's heap even when its free top cannot hold them (the heap grows; glibc's
// default maps each such block on its own, on fresh pages), and the first of them from the advised step.
TEST(BatchHeap, MediumBlocksComeFromTheHeap) {
  const BatchHeap heap = configureBatchHeap();
#ifdef DISTBAND_TEST_SANITIZED_MALLOC
  GTEST_SKIP() << "malloc is the sanitizer's";
#endif
  if (!kernelHasHugePages()) GTEST_SKIP() << "the kernel has no transparent huge pages";
  ASSERT_GT(heap.advised_bytes, 0u);
  const auto begin = reinterpret_cast<uintptr_t>(heap.advised_begin);
  constexpr size_t kBlock = size_t(24) << 20;
  void* blocks[3];
  for (void*& b : blocks) ASSERT_NE(b = std::malloc(kBlock), nullptr);  // 72 MiB: more than the 64 MiB step
  const auto brk = reinterpret_cast<uintptr_t>(::sbrk(0));
  for (int i = 0; i < 3; ++i) {
    const auto p = reinterpret_cast<uintptr_t>(blocks[i]);
    // The probe's block started less than a huge page below the advised range; the heap's blocks follow it.
    EXPECT_TRUE(p + (size_t(2) << 20) >= begin && p + kBlock <= brk) << "block " << i << " is not in the heap";
  }
  EXPECT_LT(reinterpret_cast<uintptr_t>(blocks[0]) + kBlock, begin + heap.advised_bytes)
      << "the first block is not in the advised step";
  for (void* b : blocks) std::free(b);
}

}  // namespace
}  // namespace distband
