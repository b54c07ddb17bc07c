// Fresh storage for a parallel fill: page first touches in parallel (touchPages), an allocator mixin and allocator
// that leave new elements unset (DefaultInitConstruct, NoInitAllocator), bricks made without values
// (appendUnsetBricks), the advice that large storage use transparent huge pages (adviseHugePages), storage mapped on
// its own in huge pages (mapHugeAligned; MappedAllocator for scratch arrays), the pages of storage already read given
// back early (giveBackHugePages) and one thread's arena of small runs in such chunks (ChunkArena).
// touchPages: the first write to each page of fresh storage, in parallel on the caller's TBB arena.
// Why: a page's first touch is a page fault (~2-10 µs on virtual machines, ~13 µs on some), and a container's
// zero-fill or construction loop takes them all on one thread; for storage of a megabyte or more that was a serial
// phase of its own (frame-pointer profiles, bench/serial_fraction.py). Touch the pages in parallel first, then
// construct. Storage of 2 MiB or more is also advised to use huge pages: one fault then maps 2 MiB, not 4 KiB.
// Contract: [p, p + bytes) is storage the caller owns and that holds no live object yet (raw allocation, or a
// vector's capacity past its size); one byte per 4 KiB page is overwritten. Below 1 MiB it does nothing.
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/brick.h"

namespace distband {

inline constexpr size_t kHugePageBytes = size_t(2) << 20;

/// `n` (a size, or an address) rounded down / up to a multiple of kHugePageBytes.
constexpr size_t roundDownToHugePage(size_t n) { return n & ~(kHugePageBytes - 1); }
constexpr size_t roundUpToHugePage(size_t n) { return roundDownToHugePage(n + kHugePageBytes - 1); }

/// Advises the kernel to back the whole 2 MiB pages inside [p, p + bytes) with transparent huge pages (advice only:
/// where the system has them off, or the range holds no whole one, nothing changes). Memory the caller owns, from
/// malloc or mmap; the pages around the range are left as they are.
inline void adviseHugePages(void* p, size_t bytes) {
#ifdef MADV_HUGEPAGE
  const uintptr_t begin = roundUpToHugePage(reinterpret_cast<uintptr_t>(p));
  const uintptr_t end = roundDownToHugePage(reinterpret_cast<uintptr_t>(p) + bytes);
  if (begin < end) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)p, (void)bytes;
#endif
}

/// Anonymous memory of `bytes` (rounded up to whole 2 MiB pages), 2 MiB-aligned and advised to use huge pages, mapped
/// on its own (given back to the system by unmapHugeAligned, whatever the heap keeps). Throws std::bad_alloc.
inline void* mapHugeAligned(size_t bytes) {
  const size_t rounded = roundUpToHugePage(bytes);
  void* raw = ::mmap(nullptr, rounded + kHugePageBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) throw std::bad_alloc();
  // Keep the aligned `rounded` bytes inside the mapping; give back the head before them and the tail after (never
  // empty: the head is less than a huge page).
  const uintptr_t begin = roundUpToHugePage(reinterpret_cast<uintptr_t>(raw));
  const size_t head = begin - reinterpret_cast<uintptr_t>(raw);
  if (head) ::munmap(raw, head);
  ::munmap(reinterpret_cast<void*>(begin + rounded), kHugePageBytes - head);
  adviseHugePages(reinterpret_cast<void*>(begin), rounded);
  return reinterpret_cast<void*>(begin);
}
inline void unmapHugeAligned(void* p, size_t bytes) { ::munmap(p, roundUpToHugePage(bytes)); }

/// Gives the whole 2 MiB pages inside [p, p + bytes) back to the system while their storage stays allocated: for
/// storage read once, front to back, whose rest is still to be read. Their contents are lost (reads give zeros);
/// the pages around the range are left as they are (none are split). Memory the caller owns.
inline void giveBackHugePages(void* p, size_t bytes) {
  const uintptr_t begin = roundUpToHugePage(reinterpret_cast<uintptr_t>(p));
  const uintptr_t end = roundDownToHugePage(reinterpret_cast<uintptr_t>(p) + bytes);
  if (begin < end) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_DONTNEED);
}

inline void touchPages(void* p, size_t bytes) {
  constexpr size_t kPage = 4096;
  if (bytes < (size_t(1) << 20)) return;
  adviseHugePages(p, bytes);
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

/// For arrays with an entry per grid voxel (or per plane entry). Leaves new elements uninitialised: the separable
/// passes write every element before reading it, so zeroing hundreds of MB on one thread first would only add a serial
/// pass (and its page faults) to the parallel ones. Arrays of 8 MiB or more are 2 MiB-aligned and ask for transparent
/// huge pages: their first touches (page faults) and the z pass's strided accesses (TLB misses, a page per slice) were
/// the largest costs of a whole-grid field after the passes themselves.
template <class T>
struct NoInitAllocator : std::allocator<T>, DefaultInitConstruct {
  static constexpr size_t kHugeFrom = size_t(8) << 20;
  template <class U>
  struct rebind {
    using other = NoInitAllocator<U>;
  };
  NoInitAllocator() = default;
  template <class U>
  NoInitAllocator(const NoInitAllocator<U>&) {}
  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    const size_t bytes = n * sizeof(T);
    if (bytes < kHugeFrom) return std::allocator<T>::allocate(n);
    const size_t rounded = roundUpToHugePage(bytes);
    void* p = std::aligned_alloc(kHugePageBytes, rounded);
    if (!p) throw std::bad_alloc();
    adviseHugePages(p, rounded);  // advice only: without it, 4 KiB pages
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) {
    if (n * sizeof(T) < kHugeFrom)
      std::allocator<T>::deallocate(p, n);
    else
      std::free(p);
  }
};

/// For scratch arrays filled in parallel right after they are sized (elements left unset: DefaultInitConstruct).
/// Arrays of 2 MiB or more are mapped on their own (mapHugeAligned): huge pages, and their memory goes back to the
/// system when they are freed, rather than staying in malloc's heaps where storage mapped later (bricks) cannot
/// reuse it. Smaller ones come from the heap, whose reused pages cost no page faults.
template <class T>
struct MappedAllocator : DefaultInitConstruct {
  using value_type = T;
  MappedAllocator() = default;
  template <class U>
  MappedAllocator(const MappedAllocator<U>&) {}
  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    if (n * sizeof(T) < kHugePageBytes) return std::allocator<T>().allocate(n);
    return static_cast<T*>(mapHugeAligned(n * sizeof(T)));
  }
  void deallocate(T* p, size_t n) {
    if (n * sizeof(T) < kHugePageBytes)
      std::allocator<T>().deallocate(p, n);
    else
      unmapHugeAligned(p, n * sizeof(T));
  }
  template <class U>
  bool operator==(const MappedAllocator<U>&) const {
    return true;
  }
};

/// One thread's storage for many small runs of trivially copyable `T` (each at most kChunkBytes): runs are carved
/// from 2 MiB chunks mapped on their own (mapHugeAligned), and stay valid until the arena goes, which unmaps them.
/// Per-result vectors cost a malloc each and fresh 4 KiB pages (a mesh's seed scan: ~5 k page faults of 11 k in a
/// 512^3 run). Not thread-safe.
template <class T>
class ChunkArena {
 public:
  static constexpr size_t kChunkBytes = kHugePageBytes;
  static_assert(std::is_trivially_copyable_v<T> && sizeof(T) <= kChunkBytes);
  ChunkArena() = default;
  ~ChunkArena() {
    for (void* c : chunks_) unmapHugeAligned(c, kChunkBytes);
  }
  ChunkArena(const ChunkArena&) = delete;
  ChunkArena& operator=(const ChunkArena&) = delete;

  /// Uninitialised storage for `n` elements, n * sizeof(T) <= kChunkBytes.
  T* take(size_t n) {
    if (n > size_t(end_ - next_)) {
      void* c = mapHugeAligned(kChunkBytes);
      chunks_.push_back(c);
      next_ = static_cast<T*>(c);
      end_ = next_ + kChunkBytes / sizeof(T);
    }
    T* run = next_;
    next_ += n;
    return run;
  }

 private:
  std::vector<void*> chunks_;
  T* next_ = nullptr;
  T* end_ = nullptr;
};

/// Appends `n` bricks with unset values (Brick::NoValues) to `out`, for a producer whose parallel fill then writes
/// every value (zero where not delivered): zeroing 2 KiB a brick here, on one thread, came before that fill. The pages
/// of the `n` bricks' storage are first touched in parallel (when they span 1 MiB or more) before the bricks are made:
/// their page faults were the serial part left (0.5 % of a 1-thread armadillo 512^3 half-width 20 run, frame-pointer
/// profile). Only those pages: a caller that reserved a whole segment keeps growing it chunk by chunk.
inline void appendUnsetBricks(std::vector<Brick>& out, size_t n) {
  out.reserve(out.size() + n);  // no-op when the capacity suffices
  // All the free capacity, not only these bricks' range: a segment's storage is reserved once and filled chunk by
  // chunk, and each chunk's unaligned ends would otherwise fault page by page.
  adviseHugePages(out.data() + out.size(), (out.capacity() - out.size()) * sizeof(Brick));
  touchPages(out.data() + out.size(), n * sizeof(Brick));  // capacity past size(): no object lives there yet
  for (size_t i = 0; i < n; ++i) out.emplace_back(Brick::NoValues{});
}

}  // namespace distband
