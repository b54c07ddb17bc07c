#include "core/separable/volume_edt.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/first_touch.h"
#include "core/separable/internal/limited_band.h"
#include "core/separable/internal/lines.h"
#include "core/separable/internal/segment_emission.h"
#include "core/separable/internal/volume_lines.h"
#include "core/thread_arena.h"

namespace distband {
namespace {

using separable_internal::BandMeasure;
using separable_internal::BrickClasses;
using separable_internal::CellBricks;
using separable_internal::CellOps;
using separable_internal::KnownLabels;
using separable_internal::LabelLineScratch;
using separable_internal::otherLabelLine;
using separable_internal::parabolaEnvelope;
using separable_internal::seedLine;
using separable_internal::Tagged;
using separable_internal::WholeGridBricks;

template <class C>
using GridCells = std::vector<C, NoInitAllocator<C>>;  // a cell per grid voxel

/// The whole grid: every voxel's cell, pass 1 and 2 slice by slice, pass 3 sixteen columns at a time. `measure`:
/// BandMeasure's fields (what the cells measure). False when interrupted.
template <class C, class T>
bool wholeGridCells(const Coord& dims, const T* labels, const BandMeasure& measure, const double w2[3],
                    const Interrupter* interrupter, GridCells<C>* out) {
  const int nx = dims.x, ny = dims.y, nz = dims.z;
  const size_t slice = size_t(nx) * ny;
  const bool multi = measure.multi_label;
  const bool nonzero = measure.seeds_nonzero;
  GridCells<C>& D = *out;
  D.resize(slice * nz);
  // Whole lines: their ends are the grid's faces.
  const KnownLabels whole_x = KnownLabels::wholeLine(0, measure.black_border),
                    whole_y = KnownLabels::wholeLine(1, measure.black_border),
                    whole_z = KnownLabels::wholeLine(2, measure.black_border);
  // Passes 1 and 2, slice by slice: rows along x, then columns along y inside the (cache-resident) slice.
  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
    const size_t n = size_t(std::max(nx, ny));
    std::vector<C> col(n), res(n);
    std::vector<T> col_labels(n);
    std::vector<int> v(n);
    std::vector<double> zz(2 * n + 2);
    LabelLineScratch<C> runs{int(n)};
    for (int z = r.begin(); z != r.end(); ++z) {
      if (isInterrupted(interrupter)) return;
      C* s = D.data() + size_t(z) * slice;
      const T* m = labels + size_t(z) * slice;
      for (int y = 0; y < ny; ++y) {
        const T* row = m + size_t(y) * nx;
        if (multi)
          otherLabelLine<C, T>(row, nx, whole_x, nullptr, s + size_t(y) * nx, w2[0], runs);
        else {
          C* out = s + size_t(y) * nx;
          seedLine<C>(
              nx, [&](int i) { return (row[i] != 0) == nonzero; }, [&](int i) { return uint32_t(row[i]); }, w2[0],
              [&](int i) -> const C& { return out[i]; }, [&](int i, const C& c) { out[i] = c; });
        }
      }
      for (int x = 0; x < nx; ++x) {
        for (int y = 0; y < ny; ++y) col[size_t(y)] = s[size_t(y) * nx + x];
        if (multi) {
          for (int y = 0; y < ny; ++y) col_labels[size_t(y)] = m[size_t(y) * nx + x];
          otherLabelLine<C, T>(col_labels.data(), ny, whole_y, col.data(), res.data(), w2[1], runs);
        } else {
          parabolaEnvelope(col.data(), res.data(), ny, w2[1], v.data(), zz.data());
        }
        for (int y = 0; y < ny; ++y) s[size_t(y) * nx + x] = res[size_t(y)];
      }
    }
  });
  if (isInterrupted(interrupter)) return false;
  // Pass 3, along z: 16 neighbouring columns at a time, so each z reads whole cache lines.
  constexpr int kColumns = 16;
  tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& r) {
    const size_t n = static_cast<size_t>(nz);
    std::vector<C> cols(kColumns * n), res(n);
    std::vector<T> col_labels(multi ? kColumns * n : 0);
    std::vector<int> v(n);
    std::vector<double> zz(2 * n + 2);
    LabelLineScratch<C> runs{int(n)};
    for (int y = r.begin(); y != r.end(); ++y) {
      if (isInterrupted(interrupter)) return;
      for (int x0 = 0; x0 < nx; x0 += kColumns) {
        const int w = std::min(kColumns, nx - x0);
        for (int z = 0; z < nz; ++z) {
          const size_t at = size_t(z) * slice + size_t(y) * nx + x0;
          const C* row = D.data() + at;
          for (int i = 0; i < w; ++i) cols[size_t(i) * nz + z] = row[i];
          if (multi)
            for (int i = 0; i < w; ++i) col_labels[size_t(i) * nz + z] = labels[at + i];
        }
        for (int i = 0; i < w; ++i) {
          C* col = cols.data() + size_t(i) * nz;
          if (multi)
            otherLabelLine<C, T>(col_labels.data() + size_t(i) * nz, nz, whole_z, col, col, w2[2], runs);
          else {
            parabolaEnvelope(col, res.data(), nz, w2[2], v.data(), zz.data());
            std::copy(res.begin(), res.end(), col);
          }
        }
        for (int z = 0; z < nz; ++z) {
          C* row = D.data() + size_t(z) * slice + size_t(y) * nx + x0;
          for (int i = 0; i < w; ++i) row[i] = cols[size_t(i) * nz + z];
        }
      }
    }
  });
  return !isInterrupted(interrupter);
}

/// The whole grid: every voxel, from dense cells — the seed field's (signed: seeds from the inside cells; unsigned,
/// a seed's cell is 0), or the multi-label EDT's (label 0 at 0, kMulti).
template <class C, class Inside, class T, bool kMulti>
struct WholeGridSource : WholeGridBricks {
  static constexpr bool kHasFeatures = CellOps<C>::kTagged;
  bool inside_negative;
  const T* labels;
  const GridCells<C>& outside;  // the seed field's outside, or the multi-label cells
  const GridCells<Inside>& inside;
  bool value(size_t, int, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    const size_t v = size_t(grid.denseIndex(c));
    if constexpr (kMulti) {
      *d = labels[v] ? std::sqrt(double(CellOps<C>::dist(outside[v]))) : 0.0;
    } else {
      const bool in = inside_negative && labels[v];
      *d = in ? -std::sqrt(double(CellOps<Inside>::dist(inside[v]))) : std::sqrt(double(CellOps<C>::dist(outside[v])));
    }
    return true;
  }
  int64_t feature(size_t, int, const Coord& c) const {
    const size_t v = size_t(grid.denseIndex(c));
    return labels[v] ? int64_t(labels[v]) : int64_t(CellOps<C>::label(outside[v]));
  }
};

/// The voxels within the limit, from the band's bricks: the seed field's outside voxels from `outside`, its seeds 0
/// (signed: minus their distance from `inside`); the multi-label EDT's labelled voxels from `outside`, label 0 at 0.
template <class C, class Inside, class T, bool kMulti>
struct BandSource {
  static constexpr bool kHasFeatures = CellOps<C>::kTagged;
  const Grid& grid;
  bool inside_negative;
  const T* labels;
  typename CellOps<C>::Dist cut2;
  std::vector<uint64_t> keys;                   // the union of the listed bricks (Grid::brickIndex), ascending
  std::vector<const C*> outside;                // their cells, or null
  std::vector<const Inside*> inside;
  size_t count() const { return keys.size(); }
  Coord origin(size_t i) const { return grid.brickOrigin(int64_t(keys[i])); }
  bool value(size_t i, int off, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    const bool labelled = labels[size_t(grid.denseIndex(c))] != 0;
    if (kMulti ? !labelled : labelled) {
      if (kMulti || !inside_negative) return *d = 0, true;
      // A seed of a signed field.
      if (!inside[i] || CellOps<Inside>::dist(inside[i][off]) > cut2) return false;
      return *d = -std::sqrt(double(CellOps<Inside>::dist(inside[i][off]))), true;
    }
    if (!outside[i] || CellOps<C>::dist(outside[i][off]) > cut2) return false;
    return *d = std::sqrt(double(CellOps<C>::dist(outside[i][off]))), true;
  }
  int64_t feature(size_t i, int off, const Coord& c) const {
    const uint32_t label = labels[size_t(grid.denseIndex(c))];
    return label ? int64_t(label) : int64_t(CellOps<C>::label(outside[i][off]));
  }
};

/// The run on cells C (the seed field's outside, or the multi-label EDT's) and Inside (a signed field's inside).
/// False when interrupted.
template <class C, class Inside, class T>
bool runCells(const Grid& grid, const T* labels, const VolumeMeasure& measure, const FieldRunOptions& options,
              FieldRunResult* result, const SegmentCallback& on_segment) {
  const Interrupter* interrupter = options.interrupter;
  const Vec3d& s = grid.axisScale();
  const double w2[3] = {s.x * s.x, s.y * s.y, s.z * s.z};
  const BandMeasure outside_measure{measure.labels, true, measure.black_border};
  const BandMeasure inside_measure{false, false, 0};
  const bool signed_field = !measure.labels && measure.inside_negative;
  if (std::isinf(options.limit_world)) {
    GridCells<C> outside;
    GridCells<Inside> inside;
    if (!wholeGridCells<C, T>(grid.dims(), labels, outside_measure, w2, interrupter, &outside) ||
        (signed_field && !wholeGridCells<Inside, T>(grid.dims(), labels, inside_measure, w2, interrupter, &inside)))
      return false;
    if (measure.labels)
      return separable_internal::emitSegments(
          grid, options, WholeGridSource<C, Inside, T, true>{{grid}, false, labels, outside, inside}, result, on_segment);
    return separable_internal::emitSegments(
        grid, options, WholeGridSource<C, Inside, T, false>{{grid}, signed_field, labels, outside, inside}, result,
        on_segment);
  }
  // Delivered: squared distance <= limit^2 (units); on a cubic grid an integer bound on integer squares.
  using Dist = typename CellOps<C>::Dist;
  const double limit = options.limit_world / grid.voxelSize();
  Dist cut2;
  if constexpr (std::is_integral_v<Dist>)
    cut2 = Dist(std::min(std::floor(limit * limit), double(uint32_t(1) << 31)));
  else
    cut2 = Dist(limit * limit);
  const BrickClasses classes = separable_internal::classifyBricks(grid, labels, measure.labels, interrupter);
  if (isInterrupted(interrupter)) return false;
  CellBricks<C> outside;
  CellBricks<Inside> inside;
  if (!separable_internal::cellsWithin<C, T>(grid, labels, classes, outside_measure, cut2, w2, interrupter,
                                             &outside) ||
      (signed_field && !separable_internal::cellsWithin<Inside, T>(grid, labels, classes, inside_measure,
                                                                   typename CellOps<Inside>::Dist(cut2), w2,
                                                                   interrupter, &inside)))
    return false;
  auto emit = [&](auto source) {
    return separable_internal::emitSegments(grid, options, source, result, on_segment);
  };
  BandSource<C, Inside, T, false> source{grid, signed_field, labels, cut2, {}, {}, {}};
  // Voxels delivered at 0 whatever the bricks (an unsigned field's seeds, the multi-label EDT's label 0): the bricks
  // holding one join the computed ones.
  std::vector<uint64_t> keys = outside.keys;
  keys.insert(keys.end(), inside.keys.begin(), inside.keys.end());
  const uint8_t zero_kind = measure.labels ? separable_internal::kAllMaskVoxels : separable_internal::kNoMaskVoxel;
  if (measure.labels || !measure.inside_negative)
    for (size_t b = 0; b < classes.mask.size(); ++b)
      if (classes.mask[b] != zero_kind) keys.push_back(b);
  tbb::parallel_sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  source.outside.reserve(keys.size());
  source.inside.reserve(keys.size());
  for (uint64_t k : keys) {
    source.outside.push_back(outside.find(k));
    source.inside.push_back(inside.find(k));
  }
  source.keys = std::move(keys);
  result->bricks_allocated = int64_t(outside.keys.size() + inside.keys.size());
  if (measure.labels)
    return emit(BandSource<C, Inside, T, true>{grid, false, labels, cut2, std::move(source.keys),
                                                std::move(source.outside), std::move(source.inside)});
  return emit(std::move(source));
}

}  // namespace

FieldRunResult computeSeparableVolumeField(const Grid& grid, const LabelVolume& volume, const VolumeMeasure& measure,
                                           const FieldRunOptions& options, const SegmentCallback& on_segment) {
  if (Status s = grid.validate(); !s.ok()) throw std::invalid_argument("grid: " + s.message());
  if (!volume || !(volume.dims() == grid.dims()))
    throw std::invalid_argument(fmt::format("the volume's dims {}x{}x{} are not the grid's {}x{}x{}", volume.dims().x,
                                            volume.dims().y, volume.dims().z, grid.dims().x, grid.dims().y,
                                            grid.dims().z));
  if (Status s = checkVolumeMeasure(volume, measure); !s.ok()) throw std::invalid_argument(s.message());
  if (!(options.limit_world > 0))
    throw std::invalid_argument(fmt::format("limit must be > 0 (got {})", options.limit_world));
  if (options.closest_features && measure.labels)
    throw std::invalid_argument("closest features: the multi-label EDT has none (nearest labels are the seed field's)");
  FieldRunResult result;
  auto body = [&] {
    const auto t0 = std::chrono::steady_clock::now();
    const bool nearest = options.closest_features;
    const bool ok = volume.visit([&](const auto* labels) {
      using T = std::remove_cv_t<std::remove_pointer_t<decltype(labels)>>;
      if (grid.cubic())
        return nearest ? runCells<Tagged<uint32_t>, uint32_t, T>(grid, labels, measure, options, &result, on_segment)
                       : runCells<uint32_t, uint32_t, T>(grid, labels, measure, options, &result, on_segment);
      return nearest ? runCells<Tagged<float>, float, T>(grid, labels, measure, options, &result, on_segment)
                     : runCells<float, float, T>(grid, labels, measure, options, &result, on_segment);
    });
    result.interrupted = !ok;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace distband
