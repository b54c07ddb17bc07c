// Exact closest-point geometry shared by the engine's triangle sites and the mesh seeds.
// Contract: pure functions, double precision, no allocation; thread-safe.
#pragma once

#include "core/types.h"

namespace distband {

/// The point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision Detection §5.1.5).
/// Degenerate triangles are handled (the result is then a closest point of a segment or a vertex).
Vec3d closestPointOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c);

inline double pointTriangleDistanceSqr(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).lengthSqr();
}

/// Squared distance from points to one triangle, for many queries: Ericson's region tests need only two dot
/// products per query once the edge products are precomputed (d3..d6 follow from d1, d2). Same regions and
/// formulas as closestPointOnTriangle; degenerate triangles fall back to it.
class TriangleDistance {
 public:
  TriangleDistance(const Vec3d& a, const Vec3d& b, const Vec3d& c)
      : a_(a), b_(b), c_(c), ab_(b - a), ac_(c - a), abab_(ab_.dot(ab_)), acac_(ac_.dot(ac_)), abac_(ab_.dot(ac_)) {}

  double dist2(const Vec3d& p) const {
    const Vec3d ap = p - a_;
    const double d1 = ab_.dot(ap), d2 = ac_.dot(ap);
    if (d1 <= 0 && d2 <= 0) return ap.lengthSqr();
    const double d3 = d1 - abab_, d4 = d2 - abac_;
    if (d3 >= 0 && d4 <= d3) return (ap - ab_).lengthSqr();
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return (ap - ab_ * (d1 / (d1 - d3))).lengthSqr();
    const double d5 = d1 - abac_, d6 = d2 - acac_;
    if (d6 >= 0 && d5 <= d6) return (ap - ac_).lengthSqr();
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return (ap - ac_ * (d2 / (d2 - d6))).lengthSqr();
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
      const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
      return (ap - ab_ - (ac_ - ab_) * w).lengthSqr();
    }
    const double denom = va + vb + vc;
    if (!(denom > 0)) return pointTriangleDistanceSqr(p, a_, b_, c_);
    return (ap - ab_ * (vb / denom) - ac_ * (vc / denom)).lengthSqr();
  }

 private:
  Vec3d a_, b_, c_, ab_, ac_;
  double abab_, acac_, abac_;
};

}  // namespace distband
