#include "core/points/point_set.h"

#include <cmath>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {

/// Points per leaf: a point test is a few multiplications, cheaper than a box test.
constexpr int kPointLeafSize = 8;

Status PointSet::build(const std::vector<Vec3d>& points, const std::vector<int64_t>& ids,
                       const Interrupter* interrupter, PointSet* out) {
  if (points.empty()) return Status::InvalidArgument("no point to search");
  if (!ids.empty() && ids.size() != points.size())
    return Status::InvalidArgument(fmt::format("{} ids for {} points", ids.size(), points.size()));
  for (size_t i = 0; i < points.size(); ++i)
    if (!std::isfinite(points[i].x) || !std::isfinite(points[i].y) || !std::isfinite(points[i].z))
      return Status::InvalidArgument(fmt::format("point {} has a coordinate that is not finite", i));
  const size_t n = points.size();
  std::vector<BvhBox> boxes(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16384), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) boxes[i].add(points[i]);
  });
  PointSet result;
  if (Status s = Bvh::build(boxes, kPointLeafSize, interrupter, &result.bvh_); !s.ok()) return s;
  std::vector<BvhBox>().swap(boxes);
  const std::vector<uint32_t>& order = result.bvh_.order();
  result.points_.resize(n);
  result.ids_.resize(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16384), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      result.points_[i] = points[order[i]];
      result.ids_[i] = ids.empty() ? int64_t(order[i]) : ids[order[i]];
    }
  });
  if (isInterrupted(interrupter)) return interrupter->status();
  *out = std::move(result);
  return Status::Ok();
}

bool PointSet::nearest(const Vec3d& p, double limit2, NearestPoint* out, uint32_t hint) const {
  double best2 = limit2;
  uint32_t best = UINT32_MAX;
  if (hint < points_.size() && (p - points_[hint]).lengthSqr() <= best2) {
    best2 = (p - points_[hint]).lengthSqr();
    best = hint;
  }
  bvh_.nearest(p, &best2, [&](uint32_t begin, uint32_t count) {
    for (uint32_t i = begin; i < begin + count; ++i) {
      if (i == hint) continue;
      const double d2 = (p - points_[i]).lengthSqr();
      if (d2 < best2 || (d2 == best2 && (best == UINT32_MAX || ids_[i] < ids_[best]))) {
        best2 = d2;
        best = i;
      }
    }
  });
  if (best == UINT32_MAX) return false;
  out->id = ids_[best];
  out->dist2 = best2;
  out->point = points_[best];
  out->slot = best;
  return true;
}

}  // namespace distband
