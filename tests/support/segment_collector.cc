#include "tests/support/segment_collector.h"

#include <cmath>
#include <tuple>

namespace distband {

CollectedField collectSegments(const Grid& grid, const BandOptions& o,
                               const std::function<FieldRunResult(const SegmentCallback&)>& compute) {
  CollectedField c;
  c.values.assign(size_t(grid.voxelCount()), NAN);
  c.closest.assign(size_t(grid.voxelCount()), -1);
  c.times_delivered.assign(size_t(grid.voxelCount()), 0);
  int open_segment = 0;
  bool saw_last = false;
  auto fail = [&](const char* what) {
    if (c.order_error.empty()) c.order_error = what;
  };
  c.result = compute([&](SegmentBricks&& s) {
    if (s.index != open_segment) fail("segment out of order");
    if (saw_last) fail("bricks after the last segment");
    for (size_t i = 1; i < s.bricks.size(); ++i) {
      const Coord a = s.bricks[i - 1].origin, b = s.bricks[i].origin;
      if (std::tie(a.z, a.y, a.x) >= std::tie(b.z, b.y, b.x)) fail("bricks not sorted");
    }
    if (o.max_chunk_bricks && s.bricks.size() > o.max_chunk_bricks) fail("chunk too large");
    for (const Brick& b : s.bricks) {
      if (b.mask.empty()) fail("an empty brick");
      if (o.closest_features && b.closest.size() != size_t(kBrickVoxels)) fail("a brick without closest features");
      for (int i = 0; i < kBrickVoxels; ++i) {
        if (!b.mask.test(i)) continue;
        const Coord v = b.origin + brickLocal(i);
        if (!grid.contains(v)) {
          fail("a voxel outside the grid");
          continue;
        }
        const size_t k = size_t(grid.denseIndex(v));
        c.values[k] = b.values[i];
        if (o.closest_features && b.closest.size() == size_t(kBrickVoxels)) c.closest[k] = b.closest[size_t(i)];
        ++c.times_delivered[k];
        const double d = std::abs(b.values[i]);
        const bool in = s.index == 0 ? d <= s.upper_world * (1 + 1e-6)
                                     : d > s.lower_world * (1 - 1e-6) && d <= s.upper_world * (1 + 1e-6);
        if (!in) fail("a voxel outside its segment's range");
      }
    }
    if (s.complete) ++open_segment;
    saw_last |= s.last;
  });
  if (!saw_last && !c.result.interrupted) fail("no last segment");
  return c;
}

}  // namespace distband
