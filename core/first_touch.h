// Fresh storage for a parallel fill.
// touchPages: the first write to each page of fresh storage, in parallel on the caller's TBB arena.
// Why: a page's first touch is a page fault (~2-10 µs on virtual machines), and a container's zero-fill or
// construction loop takes them all on one thread; for storage of a megabyte or more that was a serial phase of its
// own (frame-pointer profiles, bench/serial_fraction.py). Touch the pages in parallel first, then construct.
// Contract: [p, p + bytes) is storage the caller owns and that holds no live object yet (raw allocation, or a
// vector's capacity past its size); one byte per 4 KiB page is overwritten. Below 1 MiB it does nothing.
#pragma once

#include <cstddef>
#include <new>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {

inline void touchPages(void* p, size_t bytes) {
  constexpr size_t kPage = 4096;
  if (bytes < (size_t(1) << 20)) return;
  char* const base = static_cast<char*>(p);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, bytes / kPage, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) base[i * kPage] = 0;
  });
}

/// Allocator mixin: construct() without arguments default-initialises (a trivial type's bytes stay unset), so a
/// vector's resize() leaves fresh storage untouched for a parallel fill to write; with arguments it constructs.
struct DefaultInitConstruct {
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

}  // namespace distband
