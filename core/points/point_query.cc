#include "core/points/point_query.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

namespace distband {
namespace {

/// Points per task: a few hundred microseconds of work, so an interrupter is seen within a millisecond.
constexpr size_t kGrain = 256;

struct Found {
  bool within = false;
  double distance = 0;  ///< unsigned
  bool inside = false;
  Vec3d point;
  int64_t feature = -1;
  Vec3d surface_normal;  ///< meshes at distance 0
};

Vec3d unit(const Vec3d& v) {
  const double l = v.length();
  return l > 0 ? v * (1.0 / l) : Vec3d{};
}

Status checkSearch(const PointSearch& s, double limit) {
  if (!(limit > 0)) return Status::InvalidArgument(fmt::format("limit must be > 0 (got {})", limit));
  switch (s.seeds) {
    case SeedKind::kMesh:
      if (!s.mesh) return Status::InvalidArgument("a mesh search needs the mesh's triangle search");
      if (s.sign && s.sign->needsClosestTriangle() && std::isfinite(limit) &&
          !(s.far_sign && !s.far_sign->needsClosestTriangle()))
        return Status::InvalidArgument("a pseudonormal-signed search with a limit needs a sign for the points beyond it");
      return Status::Ok();
    case SeedKind::kPoints:
      return s.points ? Status::Ok() : Status::InvalidArgument("a point-seed search needs the seed points' search");
    case SeedKind::kVolume:
      return s.volume ? Status::Ok() : Status::InvalidArgument("a volume search needs the volume's search");
  }
  return Status::InvalidArgument("unknown seeds");
}

/// `hint`: where the previous point's feature sits in the search (nearby points share it), updated.
Found find(const PointSearch& s, const Vec3d& p, double limit, double limit2, bool want_normal, uint32_t* hint) {
  Found f;
  switch (s.seeds) {
    case SeedKind::kMesh: {
      ClosestTriangle c;
      if (s.mesh->closest(p, limit2, &c, *hint)) {
        *hint = c.slot;
        f.within = true;
        f.distance = std::sqrt(c.dist2);
        f.point = c.point;
        f.feature = c.triangle;
        if (s.sign) f.inside = s.sign->inside(p, c.triangle, f.distance);
        if (want_normal && c.dist2 == 0) f.surface_normal = s.mesh->normal(c);
      } else if (s.sign) {
        const MeshSign& far = s.sign->needsClosestTriangle() ? *s.far_sign : *s.sign;
        f.inside = far.inside(p, 0, 0);
      }
      break;
    }
    case SeedKind::kPoints: {
      NearestPoint n;
      if (s.points->nearest(p, limit2, &n, *hint)) {
        *hint = n.slot;
        f.within = true;
        f.distance = std::sqrt(n.dist2);
        f.point = n.point;
        f.feature = n.id;
      }
      break;
    }
    case SeedKind::kVolume: {
      NearestVoxel v;
      if (s.volume->nearest(p, limit, &v)) {
        f.within = true;
        f.distance = std::abs(v.distance);
        f.inside = v.distance < 0 || (v.distance == 0 && s.volume->insideNegative() && s.volume->inside(p));
        f.point = v.centre;
        f.feature = v.voxel;
      } else {
        f.inside = s.volume->insideNegative() && s.volume->inside(p);
      }
      break;
    }
  }
  return f;
}

/// Bits per axis of the Morton code.
constexpr int kMortonBits = 21;

uint64_t spread(uint64_t v) {  // bit i of v to bit 3i
  v &= 0x1FFFFF;
  v = (v | v << 32) & 0x1F00000000FFFFull;
  v = (v | v << 16) & 0x1F0000FF0000FFull;
  v = (v | v << 8) & 0x100F00F00F00F00Full;
  v = (v | v << 4) & 0x10C30C30C30C30C3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

/// The points' indices in Morton order of their positions: consecutive points then lie close together, so each
/// search starts from its predecessor's feature (a tight bound at once) and finds the tree's nodes in cache. Empty
/// for a few points (the order of the input is then kept).
std::vector<uint32_t> mortonOrder(const Vec3d* at, size_t count) {
  if (count < 2 * kGrain || count > UINT32_MAX) return {};
  Vec3d lo = at[0], hi = at[0];
  for (size_t i = 1; i < count; ++i) {
    lo = {std::min(lo.x, at[i].x), std::min(lo.y, at[i].y), std::min(lo.z, at[i].z)};
    hi = {std::max(hi.x, at[i].x), std::max(hi.y, at[i].y), std::max(hi.z, at[i].z)};
  }
  const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  const double scale = extent > 0 ? double((1 << kMortonBits) - 1) / extent : 0;
  std::vector<std::pair<uint64_t, uint32_t>> keys(count);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const Vec3d q = (at[i] - lo) * scale;
      keys[i] = {spread(uint64_t(q.x)) | spread(uint64_t(q.y)) << 1 | spread(uint64_t(q.z)) << 2, uint32_t(i)};
    }
  });
  tbb::parallel_sort(keys.begin(), keys.end());
  std::vector<uint32_t> order(count);
  for (size_t i = 0; i < count; ++i) order[i] = keys[i].second;
  return order;
}

}  // namespace

std::string_view pointFeatureName(SeedKind seeds) {
  switch (seeds) {
    case SeedKind::kMesh: return "triangle";
    case SeedKind::kPoints: return "point";
    case SeedKind::kVolume: return "voxel";
  }
  return "?";
}

Status queryPoints(const PointSearch& search, const Vec3d* at, size_t count, const PointQueryOptions& options,
                   const PointResults& out) {
  if (Status s = checkSearch(search, options.limit); !s.ok()) return s;
  for (size_t i = 0; i < count; ++i)
    if (!std::isfinite(at[i].x) || !std::isfinite(at[i].y) || !std::isfinite(at[i].z))
      return Status::InvalidArgument(
          fmt::format("point {} has a coordinate that is not finite ({}, {}, {})", i, at[i].x, at[i].y, at[i].z));
  const double limit = options.limit;
  const double limit2 = std::isfinite(limit) ? limit * limit : limit;
  const bool want_normal = out.gradient != nullptr;
  const Interrupter* interrupter = options.interrupter;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<uint32_t> order = mortonOrder(at, count);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, kGrain), [&](const tbb::blocked_range<size_t>& r) {
    if (isInterrupted(interrupter)) return;
    uint32_t hint = UINT32_MAX;
    for (size_t k = r.begin(); k != r.end(); ++k) {
      const size_t i = order.empty() ? k : order[k];
      const Vec3d& p = at[i];
      const Found f = find(search, p, limit, limit2, want_normal, &hint);
      const double sign = f.inside ? -1.0 : 1.0;
      if (out.distance) out.distance[i] = sign * (f.within ? f.distance : limit);
      if (out.closest_point) out.closest_point[i] = f.within ? f.point : Vec3d{nan, nan, nan};
      if (out.feature) out.feature[i] = f.within ? f.feature : -1;
      if (out.gradient) {
        Vec3d g{};
        if (f.within) g = f.distance > 0 ? unit(p - f.point) * sign : f.surface_normal;
        out.gradient[i] = g;
      }
    }
  });
  if (isInterrupted(interrupter)) return interrupter->status();
  return Status::Ok();
}

}  // namespace distband
