#include "core/separable/volume_edt.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <utility>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/separable/internal/segment_emission.h"
#include "core/separable/internal/limited_band.h"
#include "core/separable/internal/lines.h"
#include "core/seeds/volume_seeds.h"
#include "core/thread_arena.h"

namespace distband {
namespace {

using separable_internal::kFarSquared;
using separable_internal::parabolaEnvelope;
using separable_internal::WholeGridBricks;
using separable_internal::emitSegments;
using separable_internal::classifyMaskBricks;
using separable_internal::SquaredBricks;
using separable_internal::squaredDistancesWithin;
using separable_internal::kNoMaskVoxel;

constexpr uint32_t kFar = kFarSquared;  // no seed on this line (yet)

using GridSquares = std::vector<uint32_t, NoInitAllocator<uint32_t>>;  // a squared distance per grid voxel

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

// The squared distance of every voxel to the nearest voxel whose mask test equals `seeds_nonzero`; false when
// interrupted.
bool squaredDistances(const Coord& dims, const std::vector<uint8_t>& mask, bool seeds_nonzero,
                      const Interrupter* interrupter, GridSquares* out) {
  const int nx = dims.x, ny = dims.y, nz = dims.z;
  const size_t slice = size_t(nx) * ny;
  GridSquares& D = *out;
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
        parabolaEnvelope(col.data(), res.data(), ny, 1.0, v.data(), zz.data());
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
          parabolaEnvelope(cols.data() + size_t(i) * nz, res.data(), nz, 1.0, v.data(), zz.data());
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

/// The whole grid: every voxel, from dense squared distances.
struct WholeGridSource : WholeGridBricks {
  const std::vector<uint8_t>& mask;
  bool inside_negative;
  const GridSquares& outside;
  const GridSquares& inside;
  bool value(size_t, int, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    const size_t v = size_t(grid.denseIndex(c));
    const bool in = inside_negative && mask[v];
    *d = in ? -std::sqrt(double(inside[v])) : std::sqrt(double(outside[v]));
    return true;
  }
};

/// The voxels within the limit, from the separable band's bricks: outside (non-mask) voxels from `outside`; mask
/// voxels 0, or (signed) minus their distance from `inside`.
struct BandSource {
  const Grid& grid;
  const std::vector<uint8_t>& mask;
  bool inside_negative;
  uint32_t cut2;
  std::vector<uint64_t> keys;                    // the union of the listed bricks (Grid::brickIndex), ascending
  std::vector<const uint32_t*> outside, inside;  // their squared distances, or null
  size_t count() const { return keys.size(); }
  Coord origin(size_t i) const { return grid.brickOrigin(int64_t(keys[i])); }
  bool value(size_t i, int off, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    if (mask[size_t(grid.denseIndex(c))]) {
      if (!inside_negative) return *d = 0, true;
      if (!inside[i] || inside[i][off] > cut2) return false;
      return *d = -std::sqrt(double(inside[i][off])), true;
    }
    if (!outside[i] || outside[i][off] > cut2) return false;
    return *d = std::sqrt(double(outside[i][off])), true;
  }
};

}  // namespace

FieldRunResult computeSeparableVolumeField(const Grid& grid, const std::vector<uint8_t>& mask, bool inside_negative,
                                         const FieldRunOptions& options, const SegmentCallback& on_segment) {
  if (Status s = grid.validate(); !s.ok()) throw std::invalid_argument("grid: " + s.message());
  if (!grid.cubic()) throw std::invalid_argument("the separable volume EDT needs a cubic grid (for now)");
  if (int64_t(mask.size()) != grid.voxelCount())
    throw std::invalid_argument(
        fmt::format("the mask has {} bytes, the grid {} voxels", mask.size(), grid.voxelCount()));
  if (Status s = checkSeedMask(mask, inside_negative); !s.ok()) throw std::invalid_argument(s.message());
  if (!(options.limit_world > 0))
    throw std::invalid_argument(fmt::format("limit must be > 0 (got {})", options.limit_world));
  FieldRunResult result;
  auto body = [&] {
    const auto t0 = std::chrono::steady_clock::now();
    const Interrupter* interrupter = options.interrupter;
    const Coord dims = grid.dims();
    bool ok = false;
    if (std::isinf(options.limit_world)) {
      GridSquares outside, inside;  // squared distances (voxels) to the mask, and (signed) to its outside
      ok = squaredDistances(dims, mask, true, interrupter, &outside) &&
           (!inside_negative || squaredDistances(dims, mask, false, interrupter, &inside)) &&
           emitSegments(grid, options, WholeGridSource{{grid}, mask, inside_negative, outside, inside}, &result,
                        on_segment);
    } else {
      // Delivered: squared distance <= limit^2 (voxels), an integer bound on the integer squared distances.
      const double limit = options.limit_world / grid.voxelSize();
      const uint32_t cut2 = uint32_t(std::min(std::floor(limit * limit), double(uint32_t(1) << 31)));
      const std::vector<uint8_t> kinds = classifyMaskBricks(grid, mask, interrupter);
      SquaredBricks outside, inside;
      ok = !isInterrupted(interrupter) &&
           squaredDistancesWithin(grid, mask, kinds, true, cut2, interrupter, &outside) &&
           (!inside_negative || squaredDistancesWithin(grid, mask, kinds, false, cut2, interrupter, &inside));
      if (ok) {
        BandSource source{grid, mask, inside_negative, cut2, {}, {}, {}};
        // Unsigned, every mask voxel is delivered (distance 0): the bricks holding one join the outside's.
        std::vector<uint64_t> keys = outside.keys;
        keys.insert(keys.end(), inside.keys.begin(), inside.keys.end());
        if (!inside_negative)
          for (size_t b = 0; b < kinds.size(); ++b)
            if (kinds[b] != kNoMaskVoxel) keys.push_back(b);
        tbb::parallel_sort(keys.begin(), keys.end());
        keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
        source.outside.reserve(keys.size());
        source.inside.reserve(keys.size());
        for (uint64_t k : keys) {
          source.outside.push_back(outside.find(k));
          source.inside.push_back(inside.find(k));
        }
        source.keys = std::move(keys);
        result.bricks_allocated = int64_t(outside.keys.size() + inside.keys.size());
        ok = emitSegments(grid, options, source, &result, on_segment);
      }
    }
    result.interrupted = !ok;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace distband
