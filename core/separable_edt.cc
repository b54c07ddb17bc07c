#include "core/separable_edt.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/seeds/volume_seeds.h"
#include "core/thread_arena.h"

namespace distband {
namespace {

constexpr uint32_t kFar = std::numeric_limits<uint32_t>::max();  // no seed on this line (yet)

// Pass 1, along x: each voxel's squared distance to the nearest seed of its row, by two sweeps.
void rowPass(const uint8_t* mask, bool seeds_nonzero, uint32_t* out, int n) {
  int64_t last = -1;
  for (int x = 0; x < n; ++x) {
    if ((mask[x] != 0) == seeds_nonzero) last = x;
    out[x] = last < 0 ? kFar : uint32_t((x - last) * (x - last));
  }
  last = -1;
  for (int x = n - 1; x >= 0; --x) {
    if ((mask[x] != 0) == seeds_nonzero) last = x;
    if (last >= 0) out[x] = std::min<uint32_t>(out[x], uint32_t((last - x) * (last - x)));
  }
}

// Passes 2 and 3: d[q] = min_p f[p] + (q - p)², the lower envelope of the parabolas rooted at the finite f[p]
// (Felzenszwalb & Huttenlocher). `v` and `z` are scratch of n and n + 1 entries.
void parabolaPass(const uint32_t* f, uint32_t* d, int n, int* v, double* z) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kFar) continue;
    const int64_t fq = int64_t(f[q]) + int64_t(q) * q;
    double s = -std::numeric_limits<double>::infinity();
    while (k >= 0) {
      const int p = v[k];
      s = double(fq - (int64_t(f[p]) + int64_t(p) * p)) / (2.0 * (q - p));
      if (s > z[k]) break;
      --k;
    }
    ++k;
    v[k] = q;
    z[k] = k == 0 ? -std::numeric_limits<double>::infinity() : s;
    z[k + 1] = std::numeric_limits<double>::infinity();
  }
  if (k < 0) {
    std::fill(d, d + n, kFar);
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < q) ++j;
    const int64_t dq = int64_t(q - v[j]);
    d[q] = uint32_t(dq * dq + f[v[j]]);
  }
}

// The squared distance of every voxel to the nearest voxel whose mask test equals `seeds_nonzero`; false when
// interrupted.
bool squaredDistances(const Coord& dims, const std::vector<uint8_t>& mask, bool seeds_nonzero,
                      const Interrupter* interrupter, std::vector<uint32_t>* out) {
  const int nx = dims.x, ny = dims.y, nz = dims.z;
  const size_t slice = size_t(nx) * ny;
  std::vector<uint32_t>& D = *out;
  D.resize(slice * nz);
  // Passes 1 and 2, slice by slice: rows along x, then columns along y inside the (cache-resident) slice.
  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
    const size_t n = static_cast<size_t>(ny);
    std::vector<uint32_t> col(n), res(n);
    std::vector<int> v(n);
    std::vector<double> zz(n + 1);
    for (int z = r.begin(); z != r.end(); ++z) {
      if (isInterrupted(interrupter)) return;
      uint32_t* s = D.data() + size_t(z) * slice;
      const uint8_t* m = mask.data() + size_t(z) * slice;
      for (int y = 0; y < ny; ++y) rowPass(m + size_t(y) * nx, seeds_nonzero, s + size_t(y) * nx, nx);
      for (int x = 0; x < nx; ++x) {
        for (int y = 0; y < ny; ++y) col[size_t(y)] = s[size_t(y) * nx + x];
        parabolaPass(col.data(), res.data(), ny, v.data(), zz.data());
        for (int y = 0; y < ny; ++y) s[size_t(y) * nx + x] = res[size_t(y)];
      }
    }
  });
  if (isInterrupted(interrupter)) return false;
  // Pass 3, along z: 16 neighbouring columns at a time, so each z reads whole cache lines.
  constexpr int kColumns = 16;
  tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& r) {
    const size_t n = static_cast<size_t>(nz);
    std::vector<uint32_t> cols(kColumns * n), res(n);
    std::vector<int> v(n);
    std::vector<double> zz(n + 1);
    for (int y = r.begin(); y != r.end(); ++y) {
      if (isInterrupted(interrupter)) return;
      for (int x0 = 0; x0 < nx; x0 += kColumns) {
        const int w = std::min(kColumns, nx - x0);
        for (int z = 0; z < nz; ++z) {
          const uint32_t* row = D.data() + size_t(z) * slice + size_t(y) * nx + x0;
          for (int i = 0; i < w; ++i) cols[size_t(i) * nz + z] = row[i];
        }
        for (int i = 0; i < w; ++i) {
          parabolaPass(cols.data() + size_t(i) * nz, res.data(), nz, v.data(), zz.data());
          std::copy(res.begin(), res.end(), cols.begin() + ptrdiff_t(size_t(i) * nz));
        }
        for (int z = 0; z < nz; ++z) {
          uint32_t* row = D.data() + size_t(z) * slice + size_t(y) * nx + x0;
          for (int i = 0; i < w; ++i) row[i] = cols[size_t(i) * nz + z];
        }
      }
    }
  });
  return !isInterrupted(interrupter);
}

}  // namespace

EngineResult computeSeparableVolumeField(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative,
                                         const EngineOptions& options, const SegmentCallback& on_segment) {
  if (std::string e = grid.validate(); !e.empty()) throw std::invalid_argument("grid: " + e);
  if (int64_t(mask.size()) != grid.voxelCount())
    throw std::invalid_argument(fmt::format("the mask has {} bytes, the grid {} voxels", mask.size(), grid.voxelCount()));
  if (std::string e = checkSeedMask(mask, inside_negative); !e.empty()) throw std::invalid_argument(e);
  EngineResult result;
  auto body = [&] {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    const Interrupter* interrupter = options.interrupter;
    const Coord dims = grid.dims();
    std::vector<uint32_t> outside, inside;  // squared distances (voxels) to the mask, and (signed) to its outside
    if (!squaredDistances(dims, mask, true, interrupter, &outside) ||
        (inside_negative && !squaredDistances(dims, mask, false, interrupter, &inside))) {
      result.interrupted = true;
      return;
    }
    // |distance| in voxels, and its segment: (i L, (i + 1) L], segment 0 including 0 (one segment when L = 0).
    const double h = grid.voxelSize();
    const double length = options.segment_length_world > 0 ? options.segment_length_world / h : 0;
    auto distanceOf = [&](size_t i) {
      return std::sqrt(double(inside_negative && mask[i] ? inside[i] : outside[i]));
    };
    auto segmentOf = [&](double d) { return length > 0 && d > length ? int(std::ceil(d / length)) - 1 : 0; };
    // Each brick's segment range, then the bricks of every segment in (z, y, x) order.
    const Coord bd = grid.brickDims();
    const size_t bricks = size_t(bd.x) * bd.y * bd.z;
    std::vector<int> first(bricks), last(bricks);
    tbb::parallel_for(size_t(0), bricks, [&](size_t b) {
      const Coord origin{int(b % bd.x) * kBrickSize, int(b / bd.x % bd.y) * kBrickSize,
                         int(b / (size_t(bd.x) * bd.y)) * kBrickSize};
      int lo = std::numeric_limits<int>::max(), hi = 0;
      for (int z = origin.z; z < std::min(origin.z + kBrickSize, dims.z); ++z)
        for (int y = origin.y; y < std::min(origin.y + kBrickSize, dims.y); ++y)
          for (int x = origin.x; x < std::min(origin.x + kBrickSize, dims.x); ++x) {
            const int s = segmentOf(distanceOf(size_t(grid.denseIndex({x, y, z}))));
            lo = std::min(lo, s);
            hi = std::max(hi, s);
          }
      first[b] = lo;
      last[b] = hi;
    });
    const int segments = 1 + *std::max_element(last.begin(), last.end());
    std::vector<std::vector<uint32_t>> by_segment(static_cast<size_t>(segments));
    for (size_t b = 0; b < bricks; ++b)
      for (int s = first[b]; s <= last[b]; ++s) by_segment[size_t(s)].push_back(uint32_t(b));
    std::vector<int>().swap(first);
    std::vector<int>().swap(last);

    const size_t per_chunk = options.max_chunk_bricks ? options.max_chunk_bricks : std::numeric_limits<size_t>::max();
    for (int s = 0; s < segments; ++s) {
      const auto ts = Clock::now();
      SegmentStats stats;
      stats.index = s;
      stats.lower_world = length > 0 ? s * length * h : 0;
      stats.upper_world = length > 0 ? (s + 1) * length * h : std::numeric_limits<double>::infinity();
      const std::vector<uint32_t>& list = by_segment[size_t(s)];
      SegmentBricks whole;
      for (size_t c0 = 0; c0 < list.size() || c0 == 0;) {
        if (isInterrupted(interrupter)) {
          result.interrupted = true;
          return;
        }
        const size_t c1 = std::min(list.size(), c0 + std::min<size_t>(per_chunk, 8192));
        std::vector<Brick> part(c1 - c0);
        tbb::parallel_for(c0, c1, [&](size_t i) {
          const size_t b = list[i];
          Brick& brick = part[i - c0];
          brick.origin = {int(b % bd.x) * kBrickSize, int(b / bd.x % bd.y) * kBrickSize,
                          int(b / (size_t(bd.x) * bd.y)) * kBrickSize};
          for (int off = 0; off < kBrickVoxels; ++off) {
            const Coord c = brick.origin + brickLocal(off);
            if (!grid.contains(c)) continue;
            const size_t v = size_t(grid.denseIndex(c));
            const double d = distanceOf(v);
            if (segmentOf(d) != s) continue;
            brick.values[off] = float(inside_negative && mask[v] ? -d * h : d * h);
            brick.mask.set(off);
          }
        });
        // A brick spanning segments s-1..s+1 may hold none of segment s: only bricks with voxels are delivered.
        part.erase(std::remove_if(part.begin(), part.end(), [](const Brick& b) { return b.mask.empty(); }), part.end());
        for (const Brick& b : part) stats.voxels += b.mask.count();
        stats.bricks += int64_t(part.size());
        const bool done = c1 >= list.size();
        if (options.max_chunk_bricks) {
          SegmentBricks p;
          p.index = s;
          p.lower_world = stats.lower_world;
          p.upper_world = stats.upper_world;
          p.complete = done;
          p.last = done && s + 1 == segments;
          p.bricks = std::move(part);
          if (on_segment) on_segment(std::move(p));
        } else {
          whole.bricks.insert(whole.bricks.end(), std::make_move_iterator(part.begin()),
                              std::make_move_iterator(part.end()));
        }
        if (done) break;
        c0 = c1;
      }
      if (!options.max_chunk_bricks) {
        whole.index = s;
        whole.lower_world = stats.lower_world;
        whole.upper_world = stats.upper_world;
        whole.last = s + 1 == segments;
        if (on_segment) on_segment(std::move(whole));
      }
      std::vector<uint32_t>().swap(by_segment[size_t(s)]);
      stats.seconds = std::chrono::duration<double>(Clock::now() - ts).count();
      result.voxels += stats.voxels;
      result.segments.push_back(stats);
    }
    result.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace distband
