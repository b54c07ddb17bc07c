// The engine's per-voxel key and per-brick voxel bit sets.
// Contract: a key is 64 bits: float squared distance (voxels) | 27-bit site | 5-bit source direction. Positive floats
// order like their bit patterns, so "better" is an integer minimum and one atomic CAS updates everything together;
// distance ties go to the lower site, which keeps the field independent of thread scheduling. The direction is a
// stencil link along which the held site was offered (kNoDirection for the band, corrections and replays); an offer
// of the site a voxel already holds is never taken, so which valid direction is kept may vary, but it only selects
// offers that would be redundant either way (see LinkTables).
// Used by every part of the engine (core/band/internal/); header-only, no state. VoxelBits is safe for concurrent use.
#pragma once

#include <atomic>
#include <bit>
#include <cstdint>

#include "core/grid.h"
#include "core/seeds/seeds.h"

namespace distband::band_internal {

inline constexpr uint64_t kUntouched = ~uint64_t(0);
inline constexpr int kSiteBits = 27;
inline constexpr uint32_t kSiteMask = (1u << kSiteBits) - 1;
inline constexpr uint32_t kNoSiteKey = kSiteMask;  // kNoSite in the key
inline constexpr uint32_t kMaxSites = kSiteMask;   // site ids must stay below this
inline constexpr uint32_t kNoDirection = 31;

inline uint64_t packKey(float d2, uint32_t dir, uint32_t site) {
  return (uint64_t(std::bit_cast<uint32_t>(d2)) << 32) | (uint64_t(site) << 5) | dir;
}
inline float keyDist2(uint64_t k) { return std::bit_cast<float>(uint32_t(k >> 32)); }
inline uint32_t keySite(uint64_t k) { return uint32_t(k) >> 5; }
inline uint32_t keyDir(uint64_t k) { return uint32_t(k) & 31; }
inline uint32_t toKeySite(uint32_t site) { return site == kNoSite ? kNoSiteKey : site; }

/// One bit per voxel of a brick. set() and clear() are atomic read-modify-writes (other threads may set other bits
/// of the same word); set() tells whether this call set the bit.
struct VoxelBits {
  std::atomic<uint64_t> words[kBrickVoxels / 64] = {};
  bool test(int i) const { return (words[i >> 6].load(std::memory_order_relaxed) >> (i & 63)) & 1; }
  bool set(int i) {
    const uint64_t bit = uint64_t(1) << (i & 63);
    return !(words[i >> 6].fetch_or(bit, std::memory_order_relaxed) & bit);
  }
  void clear(int i) { words[i >> 6].fetch_and(~(uint64_t(1) << (i & 63)), std::memory_order_relaxed); }
};

}  // namespace distband::band_internal
