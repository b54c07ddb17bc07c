// Brick: the unit of output and transfer, an 8x8x8 block of distances (like an OpenVDB leaf / nvblox block).
// Contract: `origin` is a multiple of 8 in index space. Values are world-unit distances, negative inside when
// the field is signed. Voxel (x,y,z) of the grid lives in the brick with origin (x&~7, y&~7, z&~7) at
// offset brickOffset(x&7, y&7, z&7) = (x<<6)|(y<<3)|z — OpenVDB's LeafNode order (z fastest).
// `mask` marks the voxels that this brick message delivers; other values are unspecified.
// Plain value type; no internal synchronisation.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/grid.h"
#include "core/types.h"

namespace distband {

inline constexpr int brickOffset(int lx, int ly, int lz) { return (lx << 6) | (ly << 3) | lz; }
inline constexpr Coord brickLocal(int offset) { return {offset >> 6, (offset >> 3) & 7, offset & 7}; }

/// 512-bit voxel mask of a brick, bit i = voxel at offset i (64 bytes on the wire, little-endian words).
struct BrickMask {
  std::array<uint64_t, kBrickVoxels / 64> words{};
  void set(int i) { words[i >> 6] |= uint64_t(1) << (i & 63); }
  bool test(int i) const { return (words[i >> 6] >> (i & 63)) & 1; }
  int count() const {
    int n = 0;
    for (uint64_t w : words) n += std::popcount(w);
    return n;
  }
  bool empty() const {
    for (uint64_t w : words)
      if (w) return false;
    return true;
  }
  /// Calls visit(i) for each voxel i of the mask, in offset order (a thin band's bricks are mostly empty: set bits
  /// only). A visit that returns bool stops the walk by returning false; forEach then returns false.
  template <class Visit>
  bool forEach(Visit&& visit) const {
    for (int w = 0; w < kBrickVoxels / 64; ++w)
      for (uint64_t bits = words[size_t(w)]; bits; bits &= bits - 1) {
        const int i = w * 64 + std::countr_zero(bits);
        if constexpr (std::is_same_v<decltype(visit(i)), bool>) {
          if (!visit(i)) return false;
        } else {
          visit(i);
        }
      }
    return true;
  }
};

struct Brick {
  /// Tag of the constructor that leaves `values` unset, for producers whose parallel fill writes every value: zeroing
  /// 2 KiB a brick while constructing them (one thread, the fill's first touch of fresh pages) was a serial phase.
  struct NoValues {};
  Brick() : values{} {}
  explicit Brick(NoValues) {}

  Coord origin;
  std::array<float, kBrickVoxels> values;  // zero from Brick(), unset from Brick(NoValues)
  BrickMask mask;
  /// Closest-feature ids of the masked voxels (BandOptions::closest_features; see Seeds::FeatureKind), indexed
  /// like `values`; empty when not requested.
  std::vector<int64_t> closest;
};

/// The bricks finished by one segment of the propagation (or a chunk of them), delivered nearest-first. Every voxel
/// within the limit is delivered exactly once over a run, in the segment whose range holds its |distance|.
struct SegmentBricks {
  int index = 0;               ///< 0-based segment number
  double lower_world = 0;      ///< |distance| range of the voxels delivered: (lower, upper]; segment 0 includes 0
  double upper_world = 0;
  bool last = false;           ///< true for the final segment of a completed run (on its complete chunk)
  bool complete = true;        ///< false on all but the last chunk of a segment (BandOptions::max_chunk_bricks)
  std::vector<Brick> bricks;   ///< sorted by origin (z, y, x), one entry per brick with delivered voxels
};

}  // namespace distband
