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
using separable_internal::SegmentWindow;
using separable_internal::otherLabelLine;
using separable_internal::parabolaEnvelope;
using separable_internal::seedLine;
using separable_internal::Tagged;
using separable_internal::WholeGridBricks;

template <class C>
using GridCells = std::vector<C, NoInitAllocator<C>>;  // a cell per grid voxel

/// Passes 2 and 3 work on this many neighbouring columns at once, so each step along the axis reads and writes whole
/// cache lines (one column at a time, the strided copies in and out were a third of passes 1 and 2).
constexpr int kColumns = 16;

/// Per-thread scratch of columnPass for lines of up to n voxels.
template <class C, class T>
struct ColumnScratch {
  std::vector<C> cols, res;
  std::vector<T> labels;
  std::vector<int> v;
  std::vector<double> z;
  LabelLineScratch<C> runs;
  ColumnScratch(int n, bool multi)
      : cols(kColumns * size_t(n)),
        res(size_t(n)),
        labels(multi ? kColumns * size_t(n) : 0),
        v(size_t(n)),
        z(2 * size_t(n) + 2),
        runs(n) {}
};

/// One pass over `w` <= kColumns neighbouring lines of n cells: line i's voxel k is cells[k * stride + i] (its label
/// labels[k * stride + i]; null for the seed field, whose pass is the parabola envelope). Copied in, computed, copied
/// back. `prefetch`: the lines are far apart (a slice), so ask for the cells eight steps ahead.
template <class C, class T>
void columnPass(C* cells, const T* labels, size_t stride, int n, int w, const KnownLabels& known, double w2,
                bool prefetch, ColumnScratch<C, T>& s) {
  for (int k = 0; k < n; ++k) {
    const size_t at = size_t(k) * stride;
    if (prefetch && k + 8 < n) {  // no hardware prefetcher follows lines a slice apart
      __builtin_prefetch(cells + at + 8 * stride);
      if (labels) __builtin_prefetch(labels + at + 8 * stride);
    }
    for (int i = 0; i < w; ++i) s.cols[size_t(i) * n + k] = cells[at + i];
    if (labels)
      for (int i = 0; i < w; ++i) s.labels[size_t(i) * n + k] = labels[at + i];
  }
  for (int i = 0; i < w; ++i) {
    C* col = s.cols.data() + size_t(i) * n;
    if (labels) {
      otherLabelLine<C, T>(s.labels.data() + size_t(i) * n, n, known, col, col, w2, s.runs);
    } else {
      parabolaEnvelope(col, s.res.data(), n, w2, s.v.data(), s.z.data());
      std::copy(s.res.begin(), s.res.begin() + n, col);
    }
  }
  for (int k = 0; k < n; ++k) {
    C* row = cells + size_t(k) * stride;
    for (int i = 0; i < w; ++i) row[i] = s.cols[size_t(i) * n + k];
  }
}

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
    ColumnScratch<C, T> scratch(std::max(nx, ny), multi);
    for (int z = r.begin(); z != r.end(); ++z) {
      if (isInterrupted(interrupter)) return;
      C* s = D.data() + size_t(z) * slice;
      const T* m = labels + size_t(z) * slice;
      for (int y = 0; y < ny; ++y) {
        const T* row = m + size_t(y) * nx;
        if (multi)
          otherLabelLine<C, T>(row, nx, whole_x, nullptr, s + size_t(y) * nx, w2[0], scratch.runs);
        else {
          C* out = s + size_t(y) * nx;
          seedLine<C>(
              nx, [&](int i) { return (row[i] != 0) == nonzero; }, [&](int i) { return uint32_t(row[i]); }, w2[0],
              [&](int i) -> const C& { return out[i]; }, [&](int i, const C& c) { out[i] = c; });
        }
      }
      for (int x0 = 0; x0 < nx; x0 += kColumns)
        columnPass(s + x0, multi ? m + x0 : nullptr, size_t(nx), ny, std::min(kColumns, nx - x0), whole_y, w2[1], false,
                   scratch);
    }
  });
  if (isInterrupted(interrupter)) return false;
  // Pass 3, along z, its lines a slice apart (prefetched).
  tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& r) {
    ColumnScratch<C, T> scratch(nz, multi);
    for (int y = r.begin(); y != r.end(); ++y) {
      if (isInterrupted(interrupter)) return;
      for (int x0 = 0; x0 < nx; x0 += kColumns) {
        const size_t at = size_t(y) * nx + x0;
        columnPass(D.data() + at, multi ? labels + at : nullptr, slice, nz, std::min(kColumns, nx - x0), whole_z, w2[2],
                   true, scratch);
      }
    }
  });
  return !isInterrupted(interrupter);
}

/// The least and greatest distance (units) of the voxels of the brick at `origin` inside `grid` for which
/// `squared(offset, voxel, &v)` holds, from the least and greatest v: the sources' range() (SourceHasRange), with
/// value()'s square root, so that emitSegments sorts the bricks into the segments their voxels fall in. False when
/// none holds.
template <class Squared>
bool squaredRange(const Grid& grid, const Coord& origin, const Squared& squared, double* lo, double* hi) {
  double lo2 = std::numeric_limits<double>::infinity(), hi2 = -1;
  for (int off = 0; off < kBrickVoxels; ++off) {
    const Coord c = origin + brickLocal(off);
    double v;
    if (!grid.contains(c) || !squared(off, c, &v)) continue;
    lo2 = std::min(lo2, v);
    hi2 = std::max(hi2, v);
  }
  if (hi2 < 0) return false;
  *lo = std::sqrt(lo2);
  *hi = std::sqrt(hi2);
  return true;
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
  /// The voxel's squared distance (units), and whether its distance is negative.
  double squared(const Coord& c, bool* negative) const {
    const size_t v = size_t(grid.denseIndex(c));
    *negative = !kMulti && inside_negative && labels[v];
    if constexpr (kMulti) return labels[v] ? double(CellOps<C>::dist(outside[v])) : 0.0;
    return *negative ? double(CellOps<Inside>::dist(inside[v])) : double(CellOps<C>::dist(outside[v]));
  }
  bool value(size_t, int, const Coord& c, double* d) const {
    if (!grid.contains(c)) return false;
    bool negative;
    const double root = std::sqrt(squared(c, &negative));
    *d = negative ? -root : root;
    return true;
  }
  bool range(size_t b, double* lo, double* hi) const {
    return squaredRange(
        grid, origin(b),
        [&](int, const Coord& c, double* v) {
          bool negative;
          return *v = squared(c, &negative), true;
        },
        lo, hi);
  }
  int64_t feature(size_t, int, const Coord& c) const {
    const size_t v = size_t(grid.denseIndex(c));
    return labels[v] ? int64_t(labels[v]) : int64_t(CellOps<C>::label(outside[v]));
  }
};

/// A band's bricks in (z, y, x) order: the union of the listed bricks (Grid::brickIndex) and their cells, or null.
template <class C, class Inside>
struct BandBricks {
  std::vector<uint64_t> keys;
  std::vector<const C*> outside;
  std::vector<const Inside*> inside;
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
  const BandBricks<C, Inside>& bricks;
  const std::vector<uint8_t>& mask;  // BrickClasses::mask: a brick with all labels zero or all nonzero reads none
  size_t count() const { return bricks.keys.size(); }
  Coord origin(size_t i) const { return grid.brickOrigin(int64_t(bricks.keys[i])); }
  /// Whether the voxel (inside the grid) is delivered, with its squared distance (units) and whether its distance is
  /// negative.
  bool squared(size_t i, int off, const Coord& c, double* v, bool* negative) const {
    const uint8_t kind = mask[size_t(bricks.keys[i])];
    const bool labelled = kind == separable_internal::kSomeMaskVoxels ? labels[size_t(grid.denseIndex(c))] != 0
                                                                      : kind == separable_internal::kAllMaskVoxels;
    *negative = false;
    if (kMulti ? !labelled : labelled) {
      if (kMulti || !inside_negative) return *v = 0, true;
      // A seed of a signed field.
      const Inside* in = bricks.inside[i];
      if (!in || CellOps<Inside>::dist(in[off]) > cut2) return false;
      *negative = true;
      return *v = double(CellOps<Inside>::dist(in[off])), true;
    }
    const C* out = bricks.outside[i];
    if (!out || CellOps<C>::dist(out[off]) > cut2) return false;
    return *v = double(CellOps<C>::dist(out[off])), true;
  }
  bool value(size_t i, int off, const Coord& c, double* d) const {
    double v;
    bool negative;
    if (!grid.contains(c) || !squared(i, off, c, &v, &negative)) return false;
    *d = negative ? -std::sqrt(v) : std::sqrt(v);
    return true;
  }
  bool range(size_t i, double* lo, double* hi) const {
    return squaredRange(
        grid, origin(i),
        [&](int off, const Coord& c, double* v) {
          bool negative;
          return squared(i, off, c, v, &negative);
        },
        lo, hi);
  }
  int64_t feature(size_t i, int off, const Coord& c) const {
    const uint32_t label = labels[size_t(grid.denseIndex(c))];
    return label ? int64_t(label) : int64_t(CellOps<C>::label(bricks.outside[i][off]));
  }
};

/// The squared-distance bound (units) of the voxels within `units`: on a cubic grid an integer bound on integer
/// squares.
template <class Dist>
Dist squaredCut(double units) {
  if constexpr (std::is_integral_v<Dist>)
    return Dist(std::min(std::floor(units * units), double(uint32_t(1) << 31)));
  else
    return Dist(units * units);
}

/// The run on cells C (the seed field's outside, or the multi-label EDT's) and Inside (a signed field's inside).
template <class C, class Inside, class T>
class CellsRun {
 public:
  CellsRun(const Grid& grid, const T* labels, const VolumeMeasure& measure, const FieldRunOptions& options,
           FieldRunResult* result, const SegmentCallback& on_segment)
      : grid_(grid), labels_(labels), measure_(measure), options_(options), result_(result), on_segment_(on_segment) {
    const Vec3d& s = grid.axisScale();
    w2_[0] = s.x * s.x;
    w2_[1] = s.y * s.y;
    w2_[2] = s.z * s.z;
  }

  /// False when interrupted. Near field first, so a client gets near voxels after a fraction of the work instead of
  /// after all of it:
  ///   * with a limit, when the client takes chunks, the band is computed in two parts along z: the first few layers
  ///     that hold a boundary (a few percent of the band's work), whose near segment is streamed at once, then the
  ///     rest; what the parts' passes read twice is bounded by the first part's work. Later segments then come from
  ///     both parts.
  ///   * otherwise, when the field has more than one segment, segment 0 comes from the band within its bound (it
  ///     follows the boundary), then the rest from the whole grid or the band within the limit. The band works in
  ///     whole bricks, so within a limit of a few bricks the first segment's band costs nearly the limit's: there it
  ///     is skipped (docs/benchmarks.md, service_bench).
  bool run() {
    using Dist = typename CellOps<C>::Dist;
    const double h = grid_.voxelSize();
    const double segment = options_.segment_length_world / h, limit = options_.limit_world / h;  // units
    const bool one_segment = !(segment > 0 && limit > segment);
    if (!std::isinf(limit) && options_.max_chunk_bricks > 0) {
      if (!classify()) return false;
      return emitLimitInParts(squaredCut<Dist>(limit));
    }
    auto reachBricks = [](double units) { return std::ceil(std::floor(units) / kBrickSize); };
    const bool near_first = !one_segment && (std::isinf(limit) || reachBricks(limit) >= 4 * reachBricks(segment));
    SegmentWindow rest;
    if (near_first) {
      if (!classify()) return false;
      // A little past the segment's bound, so rounding in the sqrt cannot drop one of its voxels (the emission keeps
      // only segment 0's).
      BandPart near;
      const Dist cut2 = squaredCut<Dist>(segment * (1 + 1e-6));
      if (!bandWithin(cut2, {}, &near)) return false;
      result_->bricks_allocated = near.held();
      if (!emitBand(near.bricks, cut2, SegmentWindow{0, 0})) return false;
      rest.first = 1;
    }
    if (std::isinf(limit)) return emitWholeGrid(rest);
    if (!classify()) return false;
    BandPart band;
    const Dist cut2 = squaredCut<Dist>(limit);
    if (!bandWithin(cut2, {}, &band)) return false;
    result_->bricks_allocated = band.held();
    return emitBand(band.bricks, cut2, rest);
  }

 private:
  using Dist = typename CellOps<C>::Dist;
  /// A band's cells and the bricks it delivers.
  struct BandPart {
    CellBricks<C> outside;
    CellBricks<Inside> inside;
    BandBricks<C, Inside> bricks;
    int64_t held() const { return int64_t(outside.keys.size() + inside.keys.size()); }  ///< bricks holding cells
  };

  bool signedField() const { return !measure_.labels && measure_.inside_negative; }
  BandMeasure outsideMeasure() const { return {measure_.labels, true, measure_.black_border}; }
  static constexpr BandMeasure kInsideMeasure{false, false, 0};

  bool classify() {
    if (!classes_.mask.empty()) return true;
    classes_ = separable_internal::classifyBricks(grid_, labels_, measure_.labels, options_.interrupter);
    return !isInterrupted(options_.interrupter);
  }

  bool emitWholeGrid(SegmentWindow window) {
    GridCells<C> outside;
    GridCells<Inside> inside;
    if (!wholeGridCells<C, T>(grid_.dims(), labels_, outsideMeasure(), w2_, options_.interrupter, &outside) ||
        (signedField() &&
         !wholeGridCells<Inside, T>(grid_.dims(), labels_, kInsideMeasure, w2_, options_.interrupter, &inside)))
      return false;
    if (measure_.labels)
      return separable_internal::emitSegments(grid_, options_,
                                              WholeGridSource<C, Inside, T, true>{{grid_}, false, labels_, outside, inside},
                                              result_, on_segment_, window);
    return separable_internal::emitSegments(
        grid_, options_, WholeGridSource<C, Inside, T, false>{{grid_}, signedField(), labels_, outside, inside},
        result_, on_segment_, window);
  }

  /// The band within sqrt(cut2) units on brick layers `layers`: its cells, and the bricks that deliver a voxel.
  bool bandWithin(Dist cut2, separable_internal::BrickLayers layers, BandPart* part) {
    const Interrupter* interrupter = options_.interrupter;
    if (!separable_internal::cellsWithin<C, T>(grid_, labels_, classes_, outsideMeasure(), cut2, w2_, interrupter,
                                               &part->outside, layers) ||
        (signedField() && !separable_internal::cellsWithin<Inside, T>(grid_, labels_, classes_, kInsideMeasure,
                                                                      typename CellOps<Inside>::Dist(cut2), w2_,
                                                                      interrupter, &part->inside, layers)))
      return false;
    // Voxels delivered at 0 whatever the bricks (an unsigned field's seeds, the multi-label EDT's label 0): the bricks
    // holding one join the computed ones.
    std::vector<uint64_t> keys = part->outside.keys;
    keys.insert(keys.end(), part->inside.keys.begin(), part->inside.keys.end());
    const uint8_t zero_kind = measure_.labels ? separable_internal::kAllMaskVoxels : separable_internal::kNoMaskVoxel;
    if (measure_.labels || !measure_.inside_negative) {
      const uint64_t layer = uint64_t(grid_.brickDims().x) * uint64_t(grid_.brickDims().y);
      const uint64_t lo = uint64_t(std::max(layers.lo, 0)) * layer,
                     hi = std::min(uint64_t(std::min(layers.hi, grid_.brickDims().z)) * layer, classes_.mask.size());
      for (uint64_t b = lo; b < hi; ++b)
        if (classes_.mask[b] != zero_kind) keys.push_back(b);
    }
    tbb::parallel_sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    BandBricks<C, Inside>& bricks = part->bricks;
    bricks.outside.reserve(keys.size());
    bricks.inside.reserve(keys.size());
    for (uint64_t k : keys) {
      bricks.outside.push_back(part->outside.find(k));
      bricks.inside.push_back(part->inside.find(k));
    }
    bricks.keys = std::move(keys);
    return true;
  }

  /// Streams `window` of the band `bricks` within sqrt(cut2) units.
  bool emitBand(const BandBricks<C, Inside>& bricks, Dist cut2, SegmentWindow window) {
    if (measure_.labels)
      return separable_internal::emitSegments(
          grid_, options_, BandSource<C, Inside, T, true>{grid_, false, labels_, cut2, bricks, classes_.mask}, result_,
          on_segment_, window);
    return separable_internal::emitSegments(
        grid_, options_, BandSource<C, Inside, T, false>{grid_, signedField(), labels_, cut2, bricks, classes_.mask},
        result_, on_segment_, window);
  }

  /// The band within the limit (sqrt(cut2) units) in two parts along z (see run()).
  bool emitLimitInParts(Dist cut2) {
    const int layers = grid_.brickDims().z;
    const int split = firstPartEnd(cut2);
    if (split >= layers) {  // one part
      BandPart band;
      if (!bandWithin(cut2, {}, &band)) return false;
      result_->bricks_allocated = band.held();
      return emitBand(band.bricks, cut2, {});
    }
    BandPart first, rest;
    if (!bandWithin(cut2, {0, split}, &first)) return false;
    result_->bricks_allocated = first.held();
    if (!emitBand(first.bricks, cut2, SegmentWindow{0, 0, true}) || !bandWithin(cut2, {split, layers}, &rest))
      return false;
    result_->bricks_allocated += rest.held();
    // Both parts, in (z, y, x) order (the first part's layers come before the rest's): segment 0 of the rest, then
    // every later segment of both.
    BandBricks<C, Inside> both = std::move(first.bricks);
    const size_t delivered = both.keys.size();
    both.keys.insert(both.keys.end(), rest.bricks.keys.begin(), rest.bricks.keys.end());
    both.outside.insert(both.outside.end(), rest.bricks.outside.begin(), rest.bricks.outside.end());
    both.inside.insert(both.inside.end(), rest.bricks.inside.begin(), rest.bricks.inside.end());
    rest.bricks = {};
    SegmentWindow window;
    window.delivered = delivered;
    return emitBand(both, cut2, window);
  }

  /// Where the first part of emitLimitInParts ends (a brick layer; the layer count: no split): past the first layer
  /// holding a boundary, and on while the boundary bricks its passes read (the reach beyond its end included) stay
  /// within 1/32 of the band's.
  int firstPartEnd(Dist cut2) const {
    const std::vector<int64_t> per_layer =
        separable_internal::boundaryBricksPerLayer(grid_, classes_, outsideMeasure());
    const int layers = int(per_layer.size());
    const int reach = separable_internal::reachLayers(double(cut2), w2_[2]);
    int64_t total = 0;
    for (int64_t n : per_layer) total += n;
    int end = 0;
    while (end < layers && per_layer[size_t(end)] == 0) ++end;
    if (++end >= layers) return layers;
    int64_t read = 0;
    for (int z = 0; z < std::min(end + reach, layers); ++z) read += per_layer[size_t(z)];
    while (end < layers) {
      const int64_t next = read + (end + reach < layers ? per_layer[size_t(end + reach)] : 0);
      if (32 * next > total) break;
      read = next;
      ++end;
    }
    return end;
  }

  const Grid& grid_;
  const T* labels_;
  const VolumeMeasure& measure_;
  const FieldRunOptions& options_;
  FieldRunResult* result_;
  const SegmentCallback& on_segment_;
  double w2_[3];
  BrickClasses classes_;  // made on first use (the bands need it, the whole grid does not)
};

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
        return nearest ? CellsRun<Tagged<uint32_t>, uint32_t, T>(grid, labels, measure, options, &result, on_segment).run()
                       : CellsRun<uint32_t, uint32_t, T>(grid, labels, measure, options, &result, on_segment).run();
      return nearest ? CellsRun<Tagged<float>, float, T>(grid, labels, measure, options, &result, on_segment).run()
                     : CellsRun<float, float, T>(grid, labels, measure, options, &result, on_segment).run();
    });
    result.interrupted = !ok;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace distband
