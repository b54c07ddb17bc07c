#include "core/field/band_extent.h"

#include <algorithm>
#include <cmath>

#include <tbb/parallel_for.h>

namespace distband {
namespace {

constexpr int64_t kMaxCells = int64_t(1) << 21;

// out[i] = any(in[i - r .. i + r]) along one axis of a cell grid, in place, for every line of that axis.
void dilateAxis(std::vector<uint8_t>& cells, const Coord& n, int axis, int r) {
  const int len = axis == 0 ? n.x : axis == 1 ? n.y : n.z;
  if (r <= 0 || len <= 1) return;
  const int64_t stride = axis == 0 ? 1 : axis == 1 ? n.x : int64_t(n.x) * n.y;
  const int a = axis == 0 ? 1 : 0, b = axis == 2 ? 1 : 2;  // the two other axes
  const int na = a == 0 ? n.x : n.y, nb = b == 1 ? n.y : n.z;
  const int64_t sa = a == 0 ? 1 : n.x, sb = b == 1 ? n.x : int64_t(n.x) * n.y;
  std::vector<uint8_t> line(size_t(len), 0);
  for (int j = 0; j < nb; ++j)
    for (int i = 0; i < na; ++i) {
      const int64_t base = i * sa + j * sb;
      int in_window = 0;  // marked cells in [k - r, k + r]
      for (int k = 0; k < std::min(len, r); ++k) in_window += cells[size_t(base + k * stride)] != 0;
      for (int k = 0; k < len; ++k) {
        if (k + r < len) in_window += cells[size_t(base + (k + r) * stride)] != 0;
        line[size_t(k)] = in_window > 0;
        if (k - r >= 0) in_window -= cells[size_t(base + (k - r) * stride)] != 0;
      }
      for (int k = 0; k < len; ++k) cells[size_t(base + k * stride)] = line[size_t(k)];
    }
}

}  // namespace

BandExtent::BandExtent(const Grid& grid, double limit_voxels) : grid_(grid) {
  const Coord d = grid.dims();
  reach_ = limit_voxels + kEngineReachVoxels;
  const double diagonal = std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
  if (!(reach_ < diagonal)) {
    whole_grid_ = true;
    return;
  }
  auto cellsFor = [&](int c) {
    return Coord{(d.x + c - 1) / c, (d.y + c - 1) / c, (d.z + c - 1) / c};
  };
  for (cells_ = cellsFor(cell_); int64_t(cells_.x) * cells_.y * cells_.z > kMaxCells; cells_ = cellsFor(cell_))
    cell_ *= 2;
  marked_.assign(size_t(int64_t(cells_.x) * cells_.y * cells_.z), 0);
}

void BandExtent::addBox(const Vec3d& lo, const Vec3d& hi) {
  if (whole_grid_) return;
  const Coord d = grid_.dims();
  const double box_hi[3] = {double(d.x - 1), double(d.y - 1), double(d.z - 1)};
  const double l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
  double gap2 = 0;  // squared distance between the seed's box and the grid's box
  int c0[3], c1[3];
  const int n[3] = {cells_.x, cells_.y, cells_.z};
  for (int a = 0; a < 3; ++a) {
    if (!(l[a] <= h[a])) return;  // NaN or empty
    if (h[a] < 0) gap2 += h[a] * h[a];
    if (l[a] > box_hi[a]) gap2 += (l[a] - box_hi[a]) * (l[a] - box_hi[a]);
    // Project onto the grid's box, then to cells.
    const double pl = std::clamp(l[a], 0.0, box_hi[a]), ph = std::clamp(h[a], 0.0, box_hi[a]);
    c0[a] = std::min(n[a] - 1, int(pl) / cell_);
    c1[a] = std::min(n[a] - 1, int(ph) / cell_);
  }
  if (gap2 > reach_ * reach_) return;
  for (int z = c0[2]; z <= c1[2]; ++z)
    for (int y = c0[1]; y <= c1[1]; ++y)
      for (int x = c0[0]; x <= c1[0]; ++x) marked_[size_t((int64_t(z) * cells_.y + y) * cells_.x + x)] = 1;
}

void BandExtent::addPoint(const Vec3d& p) { addBox(p, p); }

void BandExtent::addVoxelBox(const Coord& lo, const Coord& hi) {
  addBox({double(lo.x), double(lo.y), double(lo.z)}, {double(hi.x), double(hi.y), double(hi.z)});
}

uint64_t BandExtent::voxelBound() const {
  if (whole_grid_) return uint64_t(grid_.voxelCount());
  std::vector<uint8_t> cells = marked_;
  const int r = int(std::ceil(reach_ / cell_));
  for (int axis = 0; axis < 3; ++axis) dilateAxis(cells, cells_, axis, r);
  const Coord d = grid_.dims();
  auto span = [&](int c, int dim) { return uint64_t(std::min(cell_, dim - c * cell_)); };
  uint64_t voxels = 0;
  size_t i = 0;
  for (int z = 0; z < cells_.z; ++z)
    for (int y = 0; y < cells_.y; ++y)
      for (int x = 0; x < cells_.x; ++x, ++i)
        if (cells[i]) voxels += span(x, d.x) * span(y, d.y) * span(z, d.z);
  return voxels;
}

namespace {

template <class T>
Status analyzeLabels(const Coord& d, const T* mask, const Interrupter* interrupter, VolumeFootprint* out) {
  VolumeFootprint f;
  f.dims = d;
  f.bricks = {(d.x + kBrickSize - 1) / kBrickSize, (d.y + kBrickSize - 1) / kBrickSize,
              (d.z + kBrickSize - 1) / kBrickSize};
  f.brick_flags.assign(size_t(int64_t(f.bricks.x) * f.bricks.y * f.bricks.z), 0);
  const int64_t sy = d.x, sz = int64_t(d.x) * d.y;
  // One task per layer of bricks (8 z-slices): each writes only its own layer's flags.
  std::vector<uint64_t> seeds(size_t(f.bricks.z), 0), boundaries(size_t(f.bricks.z), 0),
      label_boundaries(size_t(f.bricks.z), 0);
  tbb::parallel_for(0, f.bricks.z, [&](int bz) {
    for (int z = bz * kBrickSize; z < std::min(d.z, (bz + 1) * kBrickSize); ++z) {
      if (isInterrupted(interrupter)) return;
      for (int y = 0; y < d.y; ++y) {
        const int64_t row = z * sz + y * sy;
        uint8_t* flags = &f.brick_flags[size_t((int64_t(bz) * f.bricks.y + (y >> kBrickLog2)) * f.bricks.x)];
        for (int x = 0; x < d.x; ++x) {
          const int64_t i = row + x;
          const bool in = mask[i] != 0;
          const bool boundary =
              (x > 0 && (mask[i - 1] != 0) != in) || (x + 1 < d.x && (mask[i + 1] != 0) != in) ||
              (y > 0 && (mask[i - sy] != 0) != in) || (y + 1 < d.y && (mask[i + sy] != 0) != in) ||
              (z > 0 && (mask[i - sz] != 0) != in) || (z + 1 < d.z && (mask[i + sz] != 0) != in);
          const T l = mask[i];
          const bool label_boundary = (x > 0 && mask[i - 1] != l) || (x + 1 < d.x && mask[i + 1] != l) ||
                                      (y > 0 && mask[i - sy] != l) || (y + 1 < d.y && mask[i + sy] != l) ||
                                      (z > 0 && mask[i - sz] != l) || (z + 1 < d.z && mask[i + sz] != l);
          seeds[size_t(bz)] += in;
          boundaries[size_t(bz)] += boundary;
          label_boundaries[size_t(bz)] += label_boundary;
          flags[x >> kBrickLog2] |= uint8_t((in ? VolumeFootprint::kSeed : 0) |
                                            (boundary ? VolumeFootprint::kBoundary : 0) |
                                            (label_boundary ? VolumeFootprint::kLabelBoundary : 0));
        }
      }
    }
  });
  if (isInterrupted(interrupter)) return interrupter->status();
  for (int bz = 0; bz < f.bricks.z; ++bz) {
    f.seed_voxels += seeds[size_t(bz)];
    f.boundary_voxels += boundaries[size_t(bz)];
    f.label_boundary_voxels += label_boundaries[size_t(bz)];
  }
  *out = std::move(f);
  return Status::Ok();
}

}  // namespace

Status analyzeVolume(const LabelVolume& volume, const Interrupter* interrupter, VolumeFootprint* out) {
  return volume.visit([&](const auto* labels) { return analyzeLabels(volume.dims(), labels, interrupter, out); });
}

void addVolume(const VolumeFootprint& v, const VolumeMeasure& measure, BandExtent* extent) {
  if (extent->wholeGrid()) return;
  const uint8_t want = measure.labels            ? VolumeFootprint::kLabelBoundary
                       : measure.inside_negative ? VolumeFootprint::kBoundary
                                                 : VolumeFootprint::kSeed;
  size_t i = 0;
  for (int z = 0; z < v.bricks.z; ++z)
    for (int y = 0; y < v.bricks.y; ++y)
      for (int x = 0; x < v.bricks.x; ++x, ++i)
        if (v.brick_flags[i] & want) {
          const Coord lo{x * kBrickSize, y * kBrickSize, z * kBrickSize};
          extent->addVoxelBox(lo, {std::min(lo.x + kBrickSize, v.dims.x) - 1, std::min(lo.y + kBrickSize, v.dims.y) - 1,
                                   std::min(lo.z + kBrickSize, v.dims.z) - 1});
        }
}

}  // namespace distband
