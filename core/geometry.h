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

}  // namespace distband
