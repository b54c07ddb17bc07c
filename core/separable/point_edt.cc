#include "core/separable/point_edt.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/separable/internal/segment_emission.h"
#include "core/thread_arena.h"

namespace distband {
namespace {

using separable_internal::WholeGridBricks;
using separable_internal::emitSegments;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kBlock = 16;  // x values per task: pass 3 then reads and writes 16 neighbours (64-128 bytes) at a time

// The lower envelope of the parabolas t -> (t - apex[i])^2 + f[i], apexes strictly ascending, sampled at
// t = (t0 + q) * step for q in [0, n) (step: the axis scale, unit space): winner[q] is the index of the lowest there.
// `v` and `bound`: scratch of m and m + 1.
template <bool kScaled>
void envelopeWinners(const double* apex, const double* f, int m, double t0, double step, int n, int* v, double* bound,
                     int* winner) {
  int k = 0;
  v[0] = 0;
  bound[0] = -kInf;
  bound[1] = kInf;
  for (int q = 1; q < m; ++q) {
    double s;
    for (;;) {
      const int p = v[k];
      // Where parabolas p and q cross, written around their midpoint: apex^2 terms would round away the difference
      // of far-away points.
      s = 0.5 * (apex[q] + apex[p]) + (f[q] - f[p]) / (2 * (apex[q] - apex[p]));
      if (k == 0 || s > bound[k]) break;
      --k;
    }
    if (k == 0 && !(s > bound[0])) {
      v[0] = q;  // q lies below p everywhere
      continue;
    }
    ++k;
    v[k] = q;
    bound[k] = s;
    bound[k + 1] = kInf;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    const double t = kScaled ? (t0 + q) * step : t0 + q;
    while (bound[j + 1] < t) ++j;
    winner[q] = v[j];
  }
}

struct Line {  // points with equal (y, z): order[begin, end), ascending x
  uint32_t begin = 0, end = 0;
  double y = 0;
};
struct Plane {  // points with equal z: lines[first, last)
  uint32_t first = 0, last = 0;
  double z = 0;
};

struct Layout {
  std::vector<uint32_t> order;  // point indices sorted by (z, y, x)
  std::vector<double> xs;       // their x, in that order
  std::vector<Line> lines;
  std::vector<Plane> planes;
};

// Points beyond double range in unit space (a finite world point on a tiny voxel size) are infinitely far from every
// voxel: they join no line, and if no point is left, every voxel's nearest is point 0, at an infinite distance.
Layout layoutOf(const std::vector<Vec3d>& points) {
  Layout l;
  for (uint32_t i = 0; i < uint32_t(points.size()); ++i)
    if (std::isfinite(points[i].x) && std::isfinite(points[i].y) && std::isfinite(points[i].z)) l.order.push_back(i);
  if (l.order.empty()) l.order.push_back(0);
  tbb::parallel_sort(l.order.begin(), l.order.end(), [&](uint32_t a, uint32_t b) {
    const Vec3d &p = points[a], &q = points[b];
    return std::tie(p.z, p.y, p.x, a) < std::tie(q.z, q.y, q.x, b);
  });
  l.xs.reserve(points.size());
  for (size_t i = 0; i < l.order.size(); ++i) {
    const Vec3d& p = points[l.order[i]];
    l.xs.push_back(p.x);
    const bool new_plane = l.planes.empty() || p.z != l.planes.back().z;
    if (new_plane || p.y != l.lines.back().y) {
      if (!l.lines.empty()) l.lines.back().end = uint32_t(i);
      l.lines.push_back({uint32_t(i), 0, p.y});
    }
    if (new_plane) {
      if (!l.planes.empty()) l.planes.back().last = uint32_t(l.lines.size() - 1);
      l.planes.push_back({uint32_t(l.lines.size() - 1), 0, p.z});
    }
  }
  l.lines.back().end = uint32_t(l.order.size());
  l.planes.back().last = uint32_t(l.lines.size());
  return l;
}

/// Pass 1 at position t: the line's nearest point (the lower one of a tie) and its squared x distance.
void nearestOnLine(const Layout& l, const Line& line, double t, double* d2, uint32_t* point) {
  const double* first = l.xs.data() + line.begin;
  const double* last = l.xs.data() + line.end;
  const double* i = std::lower_bound(first, last, t);
  if (i == last || (i != first && t - i[-1] <= *i - t)) --i;
  *d2 = (t - *i) * (t - *i);
  *point = l.order[size_t(i - l.xs.data())];
}

using NearestPoints = std::vector<uint32_t, NoInitAllocator<uint32_t>>;  // a point index per grid voxel

// Passes 1 to 3: each voxel's nearest point. False when interrupted.
bool nearestPoints(const Coord& dims, const Coord& offset, const Vec3d& scale, const Layout& l,
                   const Interrupter* interrupter, NearestPoints* out) {
  const int nx = dims.x, ny = dims.y, nz = dims.z;
  const int planes = int(l.planes.size());
  const size_t slice = size_t(nx) * ny;
  const auto envelope = scale == Vec3d{1, 1, 1} ? envelopeWinners<false> : envelopeWinners<true>;
  // Pass 2's result per (plane, y, x), x fastest: the squared distance to the plane's nearest point within it.
  std::vector<double, NoInitAllocator<double>> in_plane(size_t(planes) * slice);
  std::vector<uint32_t, NoInitAllocator<uint32_t>> in_plane_point(size_t(planes) * slice);
  const int x_blocks = (nx + kBlock - 1) / kBlock;
  tbb::parallel_for(tbb::blocked_range2d<int>(0, planes, 0, x_blocks), [&](const tbb::blocked_range2d<int>& r) {
    std::vector<double> apex, f, bound;
    std::vector<uint32_t> f_point;
    std::vector<int> v, winner(static_cast<size_t>(ny));
    for (int k = r.rows().begin(); k != r.rows().end(); ++k) {
      if (isInterrupted(interrupter)) return;
      const Plane& plane = l.planes[size_t(k)];
      const int m = int(plane.last - plane.first);
      apex.resize(size_t(m));
      f.resize(size_t(m));
      f_point.resize(size_t(m));
      v.resize(size_t(m));
      bound.resize(size_t(m) + 1);
      for (int j = 0; j < m; ++j) apex[size_t(j)] = l.lines[plane.first + j].y;
      for (int xb = r.cols().begin(); xb != r.cols().end(); ++xb)
        for (int x = xb * kBlock; x < std::min(nx, (xb + 1) * kBlock); ++x) {
          const double tx = (double(x) + offset.x) * scale.x;
          for (int j = 0; j < m; ++j)
            nearestOnLine(l, l.lines[plane.first + j], tx, &f[size_t(j)], &f_point[size_t(j)]);
          envelope(apex.data(), f.data(), m, double(offset.y), scale.y, ny, v.data(), bound.data(), winner.data());
          for (int y = 0; y < ny; ++y) {
            const int w = winner[size_t(y)];
            const double dy = (double(y) + offset.y) * scale.y - apex[size_t(w)];
            const size_t at = size_t(k) * slice + size_t(y) * nx + x;
            in_plane[at] = dy * dy + f[size_t(w)];
            in_plane_point[at] = f_point[size_t(w)];
          }
        }
    }
  });
  if (isInterrupted(interrupter)) return false;
  // Pass 3, along z: kBlock neighbouring columns at a time, so each plane and each z is read or written as a run.
  std::vector<double> plane_z(static_cast<size_t>(planes));
  for (int k = 0; k < planes; ++k) plane_z[size_t(k)] = l.planes[size_t(k)].z;
  NearestPoints& nearest = *out;
  nearest.resize(slice * nz);
  // First touches in parallel, polled: pass 3 writes across every z slice from its first row on, so left to page faults
  // the whole array (GBs at 1024^3) would be faulted in by the first rows, between two polls of the interrupter.
  constexpr size_t kPageEntries = 4096 / sizeof(uint32_t), kTouchEntries = size_t(1) << 19;  // 2 MiB a task
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, nearest.size(), kTouchEntries),
      [&](const tbb::blocked_range<size_t>& r) {
        if (isInterrupted(interrupter)) return;
        for (size_t i = r.begin(); i < r.end(); i += kPageEntries) nearest[i] = 0;
      },
      tbb::simple_partitioner());
  if (isInterrupted(interrupter)) return false;
  tbb::parallel_for(tbb::blocked_range2d<int>(0, ny, 0, x_blocks), [&](const tbb::blocked_range2d<int>& r) {
    std::vector<double> f(size_t(kBlock) * planes), bound(size_t(planes) + 1);
    std::vector<uint32_t> f_point(size_t(kBlock) * planes), column(size_t(kBlock) * nz);
    std::vector<int> v(static_cast<size_t>(planes)), winner(static_cast<size_t>(nz));
    for (int y = r.rows().begin(); y != r.rows().end(); ++y) {
      if (isInterrupted(interrupter)) return;
      for (int xb = r.cols().begin(); xb != r.cols().end(); ++xb) {
        const int x0 = xb * kBlock, w = std::min(kBlock, nx - x0);
        for (int k = 0; k < planes; ++k) {
          const size_t at = size_t(k) * slice + size_t(y) * nx + x0;
          for (int i = 0; i < w; ++i) {
            f[size_t(i) * planes + k] = in_plane[at + i];
            f_point[size_t(i) * planes + k] = in_plane_point[at + i];
          }
        }
        for (int i = 0; i < w; ++i) {
          envelope(plane_z.data(), f.data() + size_t(i) * planes, planes, double(offset.z), scale.z, nz, v.data(),
                   bound.data(), winner.data());
          for (int z = 0; z < nz; ++z)
            column[size_t(z) * kBlock + i] = f_point[size_t(i) * planes + winner[size_t(z)]];
        }
        for (int z = 0; z < nz; ++z)
          std::copy_n(column.data() + size_t(z) * kBlock, w, nearest.data() + size_t(z) * slice + size_t(y) * nx + x0);
      }
    }
  });
  return !isInterrupted(interrupter);
}

/// Every voxel of the grid, its distance computed from its nearest point as the band engine computes it (kScaled: on
/// an anisotropic grid, from the voxel's unit-space position).
template <bool kScaled>
struct NearestPointSource : WholeGridBricks {
  static constexpr bool kHasFeatures = true;
  const Seeds& seeds;
  const NearestPoints& nearest;
  bool value(size_t, int, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    const Coord& o = seeds.site_offset;
    Vec3d p{double(c.x + o.x), double(c.y + o.y), double(c.z + o.z)};
    if constexpr (kScaled) {
      const Vec3d& r = grid.axisScale();
      p = {p.x * r.x, p.y * r.y, p.z * r.z};
    }
    *d = std::sqrt((p - seeds.points[nearest[size_t(grid.denseIndex(c))]]).lengthSqr());
    return true;
  }
  int64_t feature(size_t, int, const Coord& c) const {
    const uint32_t i = nearest[size_t(grid.denseIndex(c))];
    return seeds.site_feature.empty() ? int64_t(i) : int64_t(seeds.site_feature[i]);
  }
};

}  // namespace

PointLayout pointLayout(const std::vector<Vec3d>& points) {
  std::vector<std::pair<double, double>> zy(points.size());
  for (size_t i = 0; i < points.size(); ++i) zy[i] = {points[i].z, points[i].y};
  std::sort(zy.begin(), zy.end());
  PointLayout l;
  l.points = int64_t(points.size());
  for (size_t i = 0; i < zy.size(); ++i) {
    l.lines += i == 0 || zy[i] != zy[i - 1];
    l.planes += i == 0 || zy[i].first != zy[i - 1].first;
  }
  return l;
}

bool separablePointsPay(const Coord& dims, const PointLayout& layout) {
  if (layout.points <= 0) return false;
  const double y = dims.y, z = dims.z;
  return double(layout.lines) + y * double(layout.planes) <= y * z / 4;
}

FieldRunResult computeSeparablePointField(const Grid& grid, const Seeds& seeds, const FieldRunOptions& options,
                                        const SegmentCallback& on_segment) {
  if (Status s = grid.validate(); !s.ok()) throw std::invalid_argument("grid: " + s.message());
  if (seeds.kind != SiteKind::kPoint) throw std::invalid_argument("the separable point EDT needs point seeds");
  if (seeds.points.empty()) throw std::invalid_argument("the separable point EDT needs at least one point");
  if (seeds.points.size() > size_t(std::numeric_limits<uint32_t>::max()))
    throw std::invalid_argument(fmt::format("{} points are more than the separable point EDT indexes",
                                            seeds.points.size()));
  if (!seeds.site_feature.empty() && seeds.site_feature.size() != seeds.points.size())
    throw std::invalid_argument("site_feature must be empty or hold one feature per point");
  if (!std::isinf(options.limit_world) || !(options.limit_world > 0))
    throw std::invalid_argument(
        fmt::format("the separable point EDT computes the whole grid: limit must be +infinity (got {})",
                    options.limit_world));
  FieldRunResult result;
  runWithThreads(options.threads, [&] {
    const auto t0 = std::chrono::steady_clock::now();
    const Layout layout = layoutOf(seeds.points);
    NearestPoints nearest;
    const bool ok =
        nearestPoints(grid.dims(), seeds.site_offset, grid.axisScale(), layout, options.interrupter, &nearest) &&
        (grid.cubic() ? emitSegments(grid, options, NearestPointSource<false>{{grid}, seeds, nearest}, &result, on_segment)
                      : emitSegments(grid, options, NearestPointSource<true>{{grid}, seeds, nearest}, &result, on_segment));
    result.interrupted = !ok;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  });
  return result;
}

}  // namespace distband
