#include "core/io/dense_field.h"

#include <atomic>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {

DenseField::DenseField(const Grid& grid, float background)
    : grid_(grid), values_(static_cast<size_t>(grid.voxelCount()), background) {}

int64_t DenseField::copyBrick(const Brick& brick) {
  const Coord d = grid_.dims();
  const Coord o = brick.origin;
  const int64_t sy = d.x, sz = int64_t(d.x) * d.y;
  // Fast path: every voxel delivered and the brick wholly inside the grid (most bricks of a full field).
  bool full = o.x + kBrickSize <= d.x && o.y + kBrickSize <= d.y && o.z + kBrickSize <= d.z;
  for (uint64_t w : brick.mask.words) full = full && w == ~uint64_t(0);
  if (full) {
    float* base = values_.data() + grid_.denseIndex(o);
    for (int lx = 0; lx < kBrickSize; ++lx)
      for (int ly = 0; ly < kBrickSize; ++ly)
        for (int lz = 0; lz < kBrickSize; ++lz)
          base[lz * sz + ly * sy + lx] = brick.values[brickOffset(lx, ly, lz)];
    return kBrickVoxels;
  }
  int64_t n = 0;
  for (int i = 0; i < kBrickVoxels; ++i) {
    if (!brick.mask.test(i)) continue;
    const Coord c = o + brickLocal(i);
    if (!grid_.contains(c)) continue;
    values_[grid_.denseIndex(c)] = brick.values[i];
    ++n;
  }
  return n;
}

void DenseField::add(const Brick& brick) { written_ += copyBrick(brick); }

void DenseField::add(const SegmentBricks& segment) {
  // Bricks cover disjoint voxels, so they can be copied in parallel.
  std::atomic<int64_t> written{0};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, segment.bricks.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
    int64_t n = 0;
    for (size_t i = r.begin(); i != r.end(); ++i) n += copyBrick(segment.bricks[i]);
    written += n;
  });
  written_ += written.load();
}

}  // namespace distband
