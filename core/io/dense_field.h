// DenseField: a dense float array assembled from delivered bricks (for .npy output, tests and small grids).
// Contract: starts filled with `background`; add() copies the masked voxels of a brick that fall inside the grid
// (a segment's bricks are copied in parallel on the caller's TBB arena). Layout x-fastest ([z][y][x] in C order),
// matching Grid::denseIndex. Not thread-safe: one caller at a time.
#pragma once

#include <cstdint>
#include <vector>

#include "core/brick.h"
#include "core/grid.h"

namespace distband {

class DenseField {
 public:
  DenseField(const Grid& grid, float background);
  void add(const Brick& brick);
  void add(const SegmentBricks& segment);
  const Grid& grid() const { return grid_; }
  float at(const Coord& c) const { return values_[grid_.denseIndex(c)]; }
  const std::vector<float>& values() const { return values_; }
  std::vector<float>& values() { return values_; }
  int64_t written() const { return written_; }  ///< voxels written by add(), counting repeats

 private:
  int64_t copyBrick(const Brick& brick);  ///< returns the voxels written

  Grid grid_;
  std::vector<float> values_;
  int64_t written_ = 0;
};

}  // namespace distband
