// Grid: the index-space box a distance field is computed on.
// Contract: voxel (i,j,k) sits at world position origin + spacing * (i,j,k), per axis (OpenVDB's cell-centred
// convention with the transform's translation = origin; spacing = the voxel's size along x, y and z in world units).
// A cubic grid has one voxel size on every axis. Valid voxels are 0 <= i < dims.x (likewise j, k).
// Distances leave core in world units; inside it they are in *voxels*: units of voxelSize(), the cubic voxel's edge,
// or on an anisotropic grid the smallest spacing. Core's algorithms work in *unit space*, world units / voxelSize()
// measured from the origin, where voxel (i,j,k) sits at axisScale() * (i,j,k) (every scale >= 1; all 1 on a cubic
// grid, where unit space is index space): the band's sites live there, the separable passes weigh each axis by its
// scale squared.
// Immutable after construction; safe to share between threads.
#pragma once

#include <algorithm>
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

/// The largest ratio of a grid's largest spacing to its smallest (Grid::validate): the band's slacks and the
/// separable passes' float squared distances grow with it.
inline constexpr double kMaxSpacingRatio = 1000.0;

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
  /// Cubic voxels of edge `voxel_size`.
  Grid(Vec3d origin, double voxel_size, Coord dims)
      : origin_(origin), spacing_{voxel_size, voxel_size, voxel_size}, unit_(voxel_size), dims_(dims) {}
  /// Voxels of spacing.x by spacing.y by spacing.z world units (cubic when the three are equal).
  Grid(Vec3d origin, Vec3d spacing, Coord dims);

  const Vec3d& origin() const { return origin_; }
  /// World units per voxel along x, y and z.
  const Vec3d& spacing() const { return spacing_; }
  /// Core's unit of length, "a voxel": the cubic voxel's edge, else the smallest spacing.
  double voxelSize() const { return unit_; }
  bool cubic() const { return spacing_.x == spacing_.y && spacing_.y == spacing_.z; }
  /// spacing / voxelSize(): where voxel (i,j,k) sits in unit space, (1,1,1) on a cubic grid.
  const Vec3d& axisScale() const { return scale_; }
  /// The largest axis scale (1 on a cubic grid): a voxel step is at most this many units long.
  double maxAxisScale() const { return std::max(scale_.x, std::max(scale_.y, scale_.z)); }
  const Coord& dims() const { return dims_; }

  Vec3d worldOf(const Coord& c) const {
    return {origin_.x + spacing_.x * c.x, origin_.y + spacing_.y * c.y, origin_.z + spacing_.z * c.z};
  }
  /// Continuous index-space position of a world point (voxel centres at integers).
  Vec3d indexOf(const Vec3d& w) const {
    return {(w.x - origin_.x) / spacing_.x, (w.y - origin_.y) / spacing_.y, (w.z - origin_.z) / spacing_.z};
  }
  /// Unit-space position of a world point: (w - origin) / voxelSize() (indexOf on a cubic grid).
  Vec3d unitsOf(const Vec3d& w) const {
    return {(w.x - origin_.x) / unit_, (w.y - origin_.y) / unit_, (w.z - origin_.z) / unit_};
  }
  /// Unit-space position of an index-space point (the point itself on a cubic grid).
  Vec3d unitsOfIndex(const Vec3d& i) const { return {i.x * scale_.x, i.y * scale_.y, i.z * scale_.z}; }
  /// The length of `dims` voxels' diagonal in world units.
  double diagonalWorld(const Coord& d) const;
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

  /// The grid of the voxels in `box` (inside this grid): same spacing, origin at box.min's world position.
  Grid window(const VoxelBox& box) const {
    Grid g = *this;
    g.origin_ = worldOf(box.min);
    g.dims_ = box.dims;
    return g;
  }
  VoxelBox box() const { return {{}, dims_}; }
  /// The same voxels with another spacing (origin and dims kept).
  Grid withSpacing(const Vec3d& spacing) const { return Grid(origin_, spacing, dims_); }

  /// OK when usable, otherwise kInvalidArgument saying why (dims out of range, a non-finite or non-positive
  /// spacing, spacings further apart than kMaxSpacingRatio, a non-finite origin).
  Status validate() const;

  friend bool operator==(const Grid& a, const Grid& b) {
    return a.origin_ == b.origin_ && a.spacing_ == b.spacing_ && a.dims_ == b.dims_;
  }

 private:
  Vec3d origin_{};
  Vec3d spacing_{1, 1, 1};
  double unit_ = 1.0;
  Vec3d scale_{1, 1, 1};
  Coord dims_{};
};

}  // namespace distband
