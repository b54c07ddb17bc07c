#include "core/geometry.h"

namespace distband {

Vec3d TriangleDistance::degenerateOffset(const Vec3d& p, TriangleFeature* feature) const {
  auto onSegment = [&](const Vec3d& s0, const Vec3d& s1) {
    const Vec3d d = s1 - s0;
    const double len2 = d.lengthSqr();
    double t = len2 > 0 ? (p - s0).dot(d) / len2 : 0.0;
    t = t < 0 ? 0 : (t > 1 ? 1 : t);
    return p - (s0 + d * t);
  };
  const Vec3d edges[3] = {onSegment(a_, b_), onSegment(b_, c_), onSegment(c_, a_)};
  const TriangleFeature names[3] = {TriangleFeature::kEdgeAB, TriangleFeature::kEdgeBC, TriangleFeature::kEdgeCA};
  int best = 0;
  for (int i = 1; i < 3; ++i)
    if (edges[i].lengthSqr() < edges[best].lengthSqr()) best = i;
  if (feature) *feature = names[best];
  return edges[best];
}

}  // namespace distband
