#include "core/dense_field.h"

namespace distband {

DenseField::DenseField(const Grid& grid, float background)
    : grid_(grid), values_(static_cast<size_t>(grid.voxelCount()), background) {}

void DenseField::add(const Brick& brick) {
  for (int i = 0; i < kBrickVoxels; ++i) {
    if (!brick.mask.test(i)) continue;
    const Coord c = brick.origin + brickLocal(i);
    if (!grid_.contains(c)) continue;
    values_[grid_.denseIndex(c)] = brick.values[i];
    ++written_;
  }
}

}  // namespace distband
