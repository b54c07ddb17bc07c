#include "core/points/triangle_bvh.h"

#include <algorithm>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/geometry.h"

namespace distband {

/// Triangles per leaf: a triangle test costs about two box tests, and a leaf of four shares one box.
constexpr int kTriangleLeafSize = 4;

Status TriangleBvh::build(const TriangleMesh& mesh, const Interrupter* interrupter, TriangleBvh* out) {
  if (mesh.triangles.empty()) return Status::InvalidArgument("the mesh has no triangles");
  for (const auto& t : mesh.triangles)
    for (uint32_t i : t)
      if (i >= mesh.vertices.size()) return Status::InvalidArgument("a triangle refers to a vertex that does not exist");
  const size_t n = mesh.triangles.size();
  std::vector<BvhBox> boxes(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16384), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t)
      for (uint32_t v : mesh.triangles[t]) boxes[t].add(mesh.vertices[v]);
  });
  TriangleBvh result;
  if (Status s = Bvh::build(boxes, kTriangleLeafSize, interrupter, &result.bvh_); !s.ok()) return s;
  const std::vector<uint32_t>& order = result.bvh_.order();
  result.triangles_.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    if ((i & 0xFFFF) == 0 && isInterrupted(interrupter)) return interrupter->status();
    const auto& t = mesh.triangles[order[i]];
    result.triangles_.emplace_back(mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]);
  }
  result.boxes_.resize(n);
  for (size_t i = 0; i < n; ++i) result.boxes_[i] = boxes[order[i]];
  if (isInterrupted(interrupter)) return interrupter->status();
  *out = std::move(result);
  return Status::Ok();
}

bool TriangleBvh::closest(const Vec3d& p, double limit2, ClosestTriangle* out, uint32_t hint) const {
  const std::vector<uint32_t>& order = bvh_.order();
  double best2 = limit2;
  uint32_t best = UINT32_MAX;  // the position in leaf order
  Vec3d best_offset{};
  if (hint < triangles_.size()) {
    const Vec3d offset = triangles_[hint].offset(p);
    if (offset.lengthSqr() <= best2) best2 = offset.lengthSqr(), best = hint, best_offset = offset;
  }
  bvh_.nearest(p, &best2, [&](uint32_t begin, uint32_t count) {
    for (uint32_t i = begin; i < begin + count; ++i) {
      if (i == hint) continue;
      // The triangle's own box is a cheaper bound: most triangles of a visited leaf lie farther than the best.
      const BvhBox& b = boxes_[i];
      const double bx = std::max({double(b.lo[0]) - p.x, 0.0, p.x - double(b.hi[0])});
      const double by = std::max({double(b.lo[1]) - p.y, 0.0, p.y - double(b.hi[1])});
      const double bz = std::max({double(b.lo[2]) - p.z, 0.0, p.z - double(b.hi[2])});
      if (bx * bx + by * by + bz * bz > best2) continue;
      const Vec3d offset = triangles_[i].offset(p);
      const double d2 = offset.lengthSqr();
      if (d2 < best2 || (d2 == best2 && (best == UINT32_MAX || order[i] < order[best]))) {
        best2 = d2;
        best = i;
        best_offset = offset;
      }
    }
  });
  if (best == UINT32_MAX) return false;
  out->triangle = order[best];
  out->dist2 = best2;
  out->point = p - best_offset;
  out->slot = best;
  return true;
}

Vec3d TriangleBvh::normal(const ClosestTriangle& found) const {
  const Vec3d n = triangles_[found.slot].normal();
  const double l = n.length();
  return l > 0 ? n * (1.0 / l) : Vec3d{};
}

}  // namespace distband
