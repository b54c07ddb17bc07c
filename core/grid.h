// Grid: the index-space box a distance field is computed on.
// Contract: voxel (i,j,k) sits at world position origin + voxel_size * (i,j,k) (OpenVDB's cell-centred
// convention with the transform's translation = origin). Valid voxels are 0 <= i < dims.x (likewise j, k).
// Distances leave the engine in world units; inside the engine they are in voxels.
// Immutable after construction; safe to share between threads.
#pragma once

#include <cstdint>
#include <limits>
#include <string>

#include "core/status.h"
#include "core/types.h"

namespace distband {

inline constexpr int kBrickLog2 = 3;
inline constexpr int kBrickSize = 1 << kBrickLog2;  ///< voxels along a brick edge (8, like OpenVDB leaves)
inline constexpr int kBrickVoxels = kBrickSize * kBrickSize * kBrickSize;

/// The largest extent the engine accepts along one axis (steps and brick tables are sized for it).
inline constexpr int kMaxGridDim = 16384;

/// The voxel size of a grid given by its dims (or a seed volume's) without one: the voxel is the unit.
inline constexpr double kDefaultVoxelSize = 1.0;

/// A box of voxels, [min, min + dims) along each axis (a tile of a grid, or the part of it a tile delivers).
/// A distance limit as a request gives it: in voxels of the grid when voxels > 0, else in world units (+infinity:
/// none). The grid (its padding holds the limit) and the plan read the same one.
struct DistanceLimit {
  double world = std::numeric_limits<double>::infinity();
  double voxels = 0;
};

struct VoxelBox {
  Coord min{};
  Coord dims{};
  Coord end() const { return min + dims; }
  bool contains(const Coord& c) const {
    return c.x >= min.x && c.y >= min.y && c.z >= min.z && c.x < min.x + dims.x && c.y < min.y + dims.y &&
           c.z < min.z + dims.z;
  }
  bool contains(const VoxelBox& b) const {
    return b.min.x >= min.x && b.min.y >= min.y && b.min.z >= min.z && b.end().x <= end().x &&
           b.end().y <= end().y && b.end().z <= end().z;
  }
  int64_t voxelCount() const { return int64_t(dims.x) * dims.y * dims.z; }
  friend bool operator==(const VoxelBox&, const VoxelBox&) = default;
};

class Grid {
 public:
  Grid() = default;
  Grid(Vec3d origin, double voxel_size, Coord dims) : origin_(origin), voxel_size_(voxel_size), dims_(dims) {}

  const Vec3d& origin() const { return origin_; }
  double voxelSize() const { return voxel_size_; }
  const Coord& dims() const { return dims_; }

  Vec3d worldOf(const Coord& c) const {
    return {origin_.x + voxel_size_ * c.x, origin_.y + voxel_size_ * c.y, origin_.z + voxel_size_ * c.z};
  }
  /// Continuous index-space position of a world point (voxel centres at integers).
  Vec3d indexOf(const Vec3d& w) const {
    return {(w.x - origin_.x) / voxel_size_, (w.y - origin_.y) / voxel_size_, (w.z - origin_.z) / voxel_size_};
  }
  bool contains(const Coord& c) const {
    return c.x >= 0 && c.y >= 0 && c.z >= 0 && c.x < dims_.x && c.y < dims_.y && c.z < dims_.z;
  }
  int64_t voxelCount() const { return int64_t(dims_.x) * dims_.y * dims_.z; }
  /// Bricks along each axis (dims rounded up to a multiple of 8).
  Coord brickDims() const {
    return {(dims_.x + kBrickSize - 1) >> kBrickLog2, (dims_.y + kBrickSize - 1) >> kBrickLog2,
            (dims_.z + kBrickSize - 1) >> kBrickLog2};
  }
  int64_t brickCount() const {
    const Coord b = brickDims();
    return int64_t(b.x) * b.y * b.z;
  }
  /// Linear index of the brick at brick coordinates `b` (x fastest): ascending indices are the (z, y, x) order of the
  /// bricks' origins.
  int64_t brickIndex(const Coord& b) const {
    const Coord d = brickDims();
    return (int64_t(b.z) * d.y + b.y) * d.x + b.x;
  }
  /// Origin (voxel coordinates) of the brick with linear index `i` (brickIndex's inverse, times the brick size).
  Coord brickOrigin(int64_t i) const {
    const Coord d = brickDims();
    return {int(i % d.x) * kBrickSize, int(i / d.x % d.y) * kBrickSize, int(i / (int64_t(d.x) * d.y)) * kBrickSize};
  }
  /// Linear index of a voxel in a dense x-fastest array ([z][y][x] in C order, as .npy files hold it).
  int64_t denseIndex(const Coord& c) const { return (int64_t(c.z) * dims_.y + c.y) * dims_.x + c.x; }

  /// The grid of the voxels in `box` (inside this grid): same voxel size, origin at box.min's world position.
  Grid window(const VoxelBox& box) const { return Grid(worldOf(box.min), voxel_size_, box.dims); }
  VoxelBox box() const { return {{}, dims_}; }

  /// OK when usable, otherwise kInvalidArgument saying why (dims out of range, non-finite or non-positive voxel size).
  Status validate() const;

 private:
  Vec3d origin_{};
  double voxel_size_ = 1.0;
  Coord dims_{};
};

}  // namespace distband
