#include "client/batch_heap.h"

#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>

#include "core/first_touch.h"

namespace distband {

namespace {

// The heap's growth step, kept free at its top: a command allocates and frees its mesh, seeds and bricks in quick
// succession, and with glibc's default (grow and trim to the byte) each round faults its pages in afresh. Untouched
// padding costs address space, not memory.
constexpr size_t kTopPad = size_t(64) << 20;
// Blocks below this come from the heap, not from mmap of their own (glibc's largest mmap threshold; its default
// starts at 128 KiB and rises only as mapped blocks are freed, which setting M_TOP_PAD turns off).
constexpr size_t kHeapBlockMax = size_t(32) << 20;
// Grows the heap by itself plus kTopPad, so that there is heap to advise before the command allocates.
constexpr size_t kProbeBytes = size_t(1) << 20;

BatchHeap configureOnce() {
  BatchHeap out;
  ::mallopt(M_TOP_PAD, int(kTopPad));
  ::mallopt(M_MMAP_THRESHOLD, int(kHeapBlockMax));
  const auto brk_before = reinterpret_cast<uintptr_t>(::sbrk(0));
  void* volatile probe = std::malloc(kProbeBytes);  // volatile: a malloc freed unused may be elided
  const auto at = reinterpret_cast<uintptr_t>(probe);
  std::free(probe);  // free() trims the heap's top to kTopPad: the break after it is the heap kept
  const auto brk_after = reinterpret_cast<uintptr_t>(::sbrk(0));
  // The probe came from the program break's heap only if the break moved and the block lies just below it; a
  // sanitizer's malloc (or a heap that fell back to mmap) leaves the break where it was.
  const bool from_break = at != 0 && brk_before != uintptr_t(-1) && brk_after != uintptr_t(-1) &&
                          brk_after > brk_before && at + kProbeBytes >= brk_before && at < brk_after;
  if (!from_break) return out;
  const uintptr_t begin = roundUpToHugePage(at), end = roundDownToHugePage(brk_after);
  if (begin >= end) return out;
#ifdef MADV_HUGEPAGE
  if (::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE) != 0) return out;
  out.advised_begin = reinterpret_cast<const void*>(begin);
  out.advised_bytes = end - begin;
#endif
  return out;
}

}  // namespace

BatchHeap configureBatchHeap() {
  static const BatchHeap configured = configureOnce();
  return configured;
}

}  // namespace distband
