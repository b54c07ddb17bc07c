// TriangleBvh: the exact closest triangle of a mesh to any point, built once per mesh (core/points/bvh.h over its
// triangles, in world space).
// Contract:
//   * build() keeps the triangles' corners in leaf order (double, as the mesh holds them) and polls `interrupter`.
//   * closest() finds the triangle nearest p within sqrt(limit2) (+infinity: anywhere): its index in the mesh, the
//     exact squared distance and the closest point (core/geometry.h's point–triangle routine, the one the grid path's
//     triangle sites use); among triangles at the same computed distance the lowest index (those sharing the
//     closest vertex or edge may differ in the last bit). False when none lies within the limit.
//   * A near p costs O(log T) box tests and a few triangle tests; a p farther than the limit from the mesh's box
//     costs one box test.
// Immutable once built; closest() is thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "core/geometry.h"
#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/bvh.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

struct ClosestTriangle {
  uint32_t triangle = 0;  ///< index in the mesh's triangles
  double dist2 = 0;       ///< squared distance, world units
  Vec3d point;            ///< the closest point on the triangle
  uint32_t slot = 0;      ///< where the triangle sits in the search (for TriangleBvh::normal)
};

class TriangleBvh {
 public:
  /// kInvalidArgument for a mesh without triangles or with a corner out of range; the interrupter's status.
  static Status build(const TriangleMesh& mesh, const Interrupter* interrupter, TriangleBvh* out);

  /// `hint`: a triangle likely near p (e.g. the previous point's, ClosestTriangle::slot), whose distance bounds the
  /// search from the start; kNoHint for none. The result does not depend on it.
  static constexpr uint32_t kNoHint = UINT32_MAX;
  bool closest(const Vec3d& p, double limit2, ClosestTriangle* out, uint32_t hint = kNoHint) const;
  /// The unit normal of the triangle `found` names (right-handed from its corners' order; 0 when degenerate).
  Vec3d normal(const ClosestTriangle& found) const;

  size_t triangles() const { return triangles_.size(); }
  uint64_t memoryBytes() const { return bvh_.memoryBytes() + triangles_.capacity() * sizeof(TriangleDistance) + boxes_.capacity() * sizeof(BvhBox); }
  /// An upper bound on memoryBytes() and the build's peak for a mesh of `triangles` triangles.
  static uint64_t estimateBytes(uint64_t triangles) {
    return Bvh::estimateBytes(triangles) + triangles * (sizeof(TriangleDistance) + 2 * sizeof(BvhBox));
  }

 private:
  Bvh bvh_;
  /// Leaf order: slot i is triangle bvh_.order()[i], prepared for the exact test (its edge products precomputed).
  std::vector<TriangleDistance> triangles_;
  std::vector<BvhBox> boxes_;  ///< leaf order: each triangle's own box, a cheaper bound than the exact test
};

}  // namespace distband
