// Exact closest-point geometry shared by the engine's triangle sites and the mesh seeds: one routine for the point
// of a triangle closest to a query point (Ericson, Real-Time Collision Detection §5.1.5), with the feature it lies
// on, the squared distance, and the closest point all derived from it.
// Contract: pure functions, double precision, no allocation; thread-safe. Degenerate (zero-area) triangles are
// handled: the closest point is then the best point of their three edges.
#pragma once

#include <cstdint>

#include "core/types.h"

namespace distband {

/// Where on a triangle (a, b, c) a closest point lies: its face, an edge (ab, bc, ca) or a corner.
enum class TriangleFeature : uint8_t { kFace, kEdgeAB, kEdgeBC, kEdgeCA, kVertexA, kVertexB, kVertexC };

/// A triangle prepared for many queries: the region tests need only two dot products per query once the edge
/// products are precomputed (d3..d6 follow from d1, d2).
class TriangleDistance {
 public:
  TriangleDistance(const Vec3d& a, const Vec3d& b, const Vec3d& c)
      : a_(a), b_(b), c_(c), ab_(b - a), ac_(c - a), abab_(ab_.dot(ab_)), acac_(ac_.dot(ac_)), abac_(ab_.dot(ac_)) {}

  /// p minus its closest point on the triangle; `feature` (may be null) gets the feature that point lies on.
  Vec3d offset(const Vec3d& p, TriangleFeature* feature = nullptr) const {
    auto at = [feature](TriangleFeature f, const Vec3d& v) {
      if (feature) *feature = f;
      return v;
    };
    const Vec3d ap = p - a_;
    const double d1 = ab_.dot(ap), d2 = ac_.dot(ap);
    if (d1 <= 0 && d2 <= 0) return at(TriangleFeature::kVertexA, ap);
    const double d3 = d1 - abab_, d4 = d2 - abac_;
    if (d3 >= 0 && d4 <= d3) return at(TriangleFeature::kVertexB, ap - ab_);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(TriangleFeature::kEdgeAB, ap - ab_ * (d1 / (d1 - d3)));
    const double d5 = d1 - abac_, d6 = d2 - acac_;
    if (d6 >= 0 && d5 <= d6) return at(TriangleFeature::kVertexC, ap - ac_);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(TriangleFeature::kEdgeCA, ap - ac_ * (d2 / (d2 - d6)));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
      const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
      return at(TriangleFeature::kEdgeBC, ap - ab_ - (ac_ - ab_) * w);
    }
    const double denom = va + vb + vc;
    if (!(denom > 0)) return degenerateOffset(p, feature);
    return at(TriangleFeature::kFace, ap - ab_ * (vb / denom) - ac_ * (vc / denom));
  }

  double dist2(const Vec3d& p) const { return offset(p).lengthSqr(); }
  /// The (unnormalised) normal ab x ac.
  Vec3d normal() const { return ab_.cross(ac_); }
  Vec3d closest(const Vec3d& p, TriangleFeature* feature = nullptr) const { return p - offset(p, feature); }

 private:
  Vec3d degenerateOffset(const Vec3d& p, TriangleFeature* feature) const;  ///< best of the three edges

  Vec3d a_, b_, c_, ab_, ac_;
  double abab_, acac_, abac_;
};

/// The point of triangle (a, b, c) closest to p, and (optionally) the feature it lies on.
inline Vec3d closestPointOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c,
                                    TriangleFeature* feature = nullptr) {
  return TriangleDistance(a, b, c).closest(p, feature);
}

inline double pointTriangleDistanceSqr(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  return TriangleDistance(a, b, c).dist2(p);
}

}  // namespace distband
