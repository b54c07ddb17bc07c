// Tests for client/batch_heap: after configureBatchHeap() the heap's kept step is advised to use huge pages (the
// kernel's own mapping flags say so) and blocks below 32 MiB come from the heap.
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

// The policy is for a fresh process (first thing in main): each check runs in a child that re-executes this test
// binary for that test alone (the "threadsafe" death-test style), not in this process, whose heap the other tests have
// already grown. A child exits 0 when every check holds and prints the first that fails.
int fail(const std::string& why) {
  std::fprintf(stderr, "%s\n", why.c_str());
  return 1;
}

// The heap's kept step is advised: the kernel's flags for the mapping at both of its ends say "hg".
int checkAdvice() {
  const BatchHeap heap = configureBatchHeap();
  if (heap.advised_bytes < (size_t(60) << 20)) return fail("advised " + std::to_string(heap.advised_bytes) + " bytes");
  if (reinterpret_cast<uintptr_t>(heap.advised_begin) % (size_t(2) << 20) != 0) return fail("unaligned begin");
  const std::string first = vmFlagsAt(heap.advised_begin);
  const std::string last = vmFlagsAt(static_cast<const char*>(heap.advised_begin) + heap.advised_bytes - 1);
  if (!hasFlag(first, "hg")) return fail("first page: " + first);
  if (!hasFlag(last, "hg")) return fail("last page: " + last);
  if (configureBatchHeap().advised_begin != heap.advised_begin) return fail("a second call changed the result");
  return 0;
}

// Blocks below 32 MiB come from the break's heap even when its free top cannot hold them (the heap grows; glibc's
// default maps each such block on its own, on fresh pages), and the first of them from the advised step.
int checkMediumBlocks() {
  const BatchHeap heap = configureBatchHeap();
  if (heap.advised_bytes == 0) return fail("nothing advised");
  const auto begin = reinterpret_cast<uintptr_t>(heap.advised_begin);
  constexpr size_t kBlock = size_t(24) << 20;
  void* blocks[3];
  for (void*& b : blocks)
    if (!(b = std::malloc(kBlock))) return fail("malloc failed");  // 72 MiB: more than the 64 MiB step
  const auto brk = reinterpret_cast<uintptr_t>(::sbrk(0));
  for (int i = 0; i < 3; ++i) {
    const auto p = reinterpret_cast<uintptr_t>(blocks[i]);
    // The probe's block started less than a huge page below the advised range; the heap's blocks follow it.
    if (!(p + (size_t(2) << 20) >= begin && p + kBlock <= brk))
      return fail("block " + std::to_string(i) + " is not in the heap");
  }
  if (reinterpret_cast<uintptr_t>(blocks[0]) + kBlock >= begin + heap.advised_bytes)
    return fail("the first block is not in the advised step");
  for (void* b : blocks) std::free(b);
  return 0;
}

bool skipReason(std::string* why) {
#ifdef DISTBAND_TEST_SANITIZED_MALLOC
  *why = "malloc is the sanitizer's: it does not grow the program break (the policy skips its advice)";
  return true;
#endif
  if (!kernelHasHugePages()) {
    *why = "the kernel has no transparent huge pages";
    return true;
  }
  return false;
}

TEST(BatchHeap, AdvisesTheHeapsStepForHugePages) {
  if (std::string why; skipReason(&why)) GTEST_SKIP() << why;
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(std::exit(checkAdvice()), ::testing::ExitedWithCode(0), "");
}

TEST(BatchHeap, MediumBlocksComeFromTheHeap) {
  if (std::string why; skipReason(&why)) GTEST_SKIP() << why;
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(std::exit(checkMediumBlocks()), ::testing::ExitedWithCode(0), "");
}

// Under a sanitizer the policy leaves the heap alone and says so.
TEST(BatchHeap, SanitizedMallocGetsNoAdvice) {
#ifndef DISTBAND_TEST_SANITIZED_MALLOC
  GTEST_SKIP() << "malloc is glibc's";
#else
  EXPECT_EQ(configureBatchHeap().advised_bytes, 0u);
#endif
}

}  // namespace
}  // namespace distband
