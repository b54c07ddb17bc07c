// PointSet: the exact nearest of a set of points to any point (core/points/bvh.h over the points) — seed points, and
// the seed voxels' centres of a volume (core/points/volume_search.h).
// Contract:
//   * build() takes the points (finite, world units) and an id per point (empty: the point's index) and polls
//     `interrupter`.
//   * nearest() finds the point nearest p within sqrt(limit2) (+infinity: anywhere): its id, the exact squared
//     distance (computed in double from the coordinates) and the point; among points at the same computed distance
//     the lowest id. False when none lies within the limit.
// Immutable once built; nearest() is thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "core/interrupter.h"
#include "core/points/bvh.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

struct NearestPoint {
  int64_t id = -1;
  double dist2 = 0;
  Vec3d point;
  uint32_t slot = 0;  ///< where the point sits in the search (a hint for the next search)
};

class PointSet {
 public:
  /// kInvalidArgument for no point, a non-finite coordinate or ids of another length; the interrupter's status.
  static Status build(const std::vector<Vec3d>& points, const std::vector<int64_t>& ids,
                      const Interrupter* interrupter, PointSet* out);

  /// `hint`: where a point likely near p sits (NearestPoint::slot of a previous answer), whose distance bounds the
  /// search from the start; kNoHint for none. The result does not depend on it.
  static constexpr uint32_t kNoHint = UINT32_MAX;
  bool nearest(const Vec3d& p, double limit2, NearestPoint* out, uint32_t hint = kNoHint) const;

  size_t size() const { return points_.size(); }
  uint64_t memoryBytes() const {
    return bvh_.memoryBytes() + points_.capacity() * sizeof(Vec3d) + ids_.capacity() * sizeof(int64_t);
  }
  /// An upper bound on memoryBytes() and the build's peak for `points` points.
  static uint64_t estimateBytes(uint64_t points) {
    return Bvh::estimateBytes(points) + points * (sizeof(Vec3d) + sizeof(int64_t) + sizeof(BvhBox));
  }

 private:
  Bvh bvh_;
  std::vector<Vec3d> points_;  ///< leaf order
  std::vector<int64_t> ids_;   ///< leaf order
};

}  // namespace distband
