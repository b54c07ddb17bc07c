// distband core value types: integer voxel coordinates and double 3-vectors.
// Contract: plain values, no invariants, freely copyable; safe to share read-only between threads.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace distband {

/// Integer index-space coordinate of a voxel (or of a brick origin).
struct Coord {
  int32_t x = 0, y = 0, z = 0;
  friend bool operator==(const Coord&, const Coord&) = default;
  Coord operator+(const Coord& o) const { return {x + o.x, y + o.y, z + o.z}; }
};

/// Hash of a Coord for unordered containers (sparse trees and meshes keyed by voxel or leaf origin).
struct CoordHash {
  size_t operator()(const Coord& c) const {
    return size_t(uint32_t(c.x)) * 0x9E3779B97F4A7C15ull ^ size_t(uint32_t(c.y)) * 0xC2B2AE3D27D4EB4Full ^
           size_t(uint32_t(c.z)) * 0x165667B19E3779F9ull;
  }
};

/// Double-precision 3-vector used for world and continuous index-space positions.
struct Vec3d {
  double x = 0, y = 0, z = 0;
  Vec3d operator+(const Vec3d& o) const { return {x + o.x, y + o.y, z + o.z}; }
  Vec3d operator-(const Vec3d& o) const { return {x - o.x, y - o.y, z - o.z}; }
  Vec3d operator*(double s) const { return {x * s, y * s, z * s}; }
  double dot(const Vec3d& o) const { return x * o.x + y * o.y + z * o.z; }
  Vec3d cross(const Vec3d& o) const { return {y * o.z - z * o.y, z * o.x - x * o.z, x * o.y - y * o.x}; }
  double lengthSqr() const { return dot(*this); }
  double length() const { return std::sqrt(lengthSqr()); }
  friend bool operator==(const Vec3d&, const Vec3d&) = default;
};

}  // namespace distband
