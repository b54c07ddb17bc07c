// Point-seed QueryRequests for tests and benches: the proto message a client would send for points on an
// N-voxel grid, so every caller builds it the same way. Header-only.
#pragma once

#include <cstdint>
#include <vector>

#include "core/grid.h"
#include "distband/v1/distband.pb.h"

namespace distband {

/// Points (world coordinates) on a grid of `dims` voxels of size `h` at the origin; `segment` and `limit` in world
/// units (0: the defaults, one segment and no limit).
inline v1::QueryRequest pointsRequest(const std::vector<Vec3d>& points, Coord dims, double h, double segment,
                                      double limit) {
  v1::QueryRequest r;
  for (const Vec3d& p : points) {
    v1::Vec3* v = r.mutable_points()->add_points();
    v->set_x(p.x);
    v->set_y(p.y);
    v->set_z(p.z);
  }
  r.mutable_grid()->set_voxel_size(h);
  r.mutable_grid()->mutable_dims()->set_x(uint32_t(dims.x));
  r.mutable_grid()->mutable_dims()->set_y(uint32_t(dims.y));
  r.mutable_grid()->mutable_dims()->set_z(uint32_t(dims.z));
  r.set_segment_length(segment);
  r.set_limit(limit);
  return r;
}

}  // namespace distband
