// Test support: runs a field computation and collects what it streams, checking the streaming contract of
// core/band/band_engine.h on the way — segments in order, each brick non-empty and sorted by origin (z, y, x), chunks no larger
// than options.max_chunk_bricks, every delivered voxel inside its segment's range, a last segment unless interrupted.
// Contract: `compute` runs the computation with the callback it is given (e.g. a lambda calling
// computeSeparableVolumeField). Per grid voxel (Grid::denseIndex): the value last delivered (NaN if none), its
// closest feature (-1 if none or not requested) and how many times it was delivered; order_error says what broke
// the contract first ("" if nothing). Single-threaded callback use, like the engine's.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/band/band_engine.h"
#include "core/grid.h"

namespace distband {

struct CollectedField {
  std::vector<float> values;
  std::vector<int64_t> closest;
  std::vector<int> times_delivered;
  std::string order_error;
  FieldRunResult result;
};

CollectedField collectSegments(const Grid& grid, const BandOptions& options,
                               const std::function<FieldRunResult(const SegmentCallback&)>& compute);

}  // namespace distband
