// The CLI's malloc policy for a batch command (one job, then exit): large blocks come from malloc's main heap, which
// grows in 64 MiB steps and whose first step is advised to use transparent huge pages (2 MiB pages).
// Why: a fresh 4 KiB page costs a page fault, ~12 µs on the virtual machines this runs on (a 256^3 mesh run took
// 3.3 k of them, ~17 % of its wall time); glibc serves blocks of 128 KiB or more by mmap, each one's pages fresh, and
// none on huge pages. With the blocks below 32 MiB in the heap and the heap on huge pages, the same run takes ~1 k
// faults and 14 % less wall time (docs/benchmarks.md, "The CLI's heap").
// Contract: call first thing in main(), before threads start (later calls change nothing). Where malloc is not glibc's
// (a sanitizer's), or the heap cannot grow by the program break, the advice is skipped and only the mallopt settings
// remain; nothing fails. The long-running server does not use this: its heap stays glibc's default (blocks given back
// when freed).
#pragma once

#include <cstddef>

namespace distband {

struct BatchHeap {
  size_t advised_bytes = 0;  ///< heap bytes advised to use huge pages (0: skipped)
  const void* advised_begin = nullptr;
};

/// Applies the policy above once; returns what was advised (later calls: the first call's result).
BatchHeap configureBatchHeap();

}  // namespace distband
