// Segment emission of the separable EDTs (core/separable/volume_edt.cc, point_edt.cc): a field that is already
// computed, streamed under the run contract.
// Contract of emitSegments(grid, options, source, result, on_segment): streams a field that is already computed,
// under the run contract (core/field/field_run.h) — segments of options.segment_length_world nearest first, each
// voxel delivered once in the segment its |distance| falls in, bricks in (z, y, x) order, chunks of
// options.max_chunk_bricks with the last one marked complete, the final segment marked last; per-segment stats are
// appended to `result`. `Source` lists the bricks in (z, y, x) order:
//   size_t count(); Coord origin(i); bool value(i, offset, voxel, double* d) — true when the voxel is delivered, with
//   its signed distance d in voxels (called from many threads, once per voxel to fill the bricks, and once more to
//   sort them into segments unless the source has range()); optionally `static constexpr bool kHasFeatures = true`
//   and int64_t feature(i, offset, voxel), the voxel's closest feature (Brick::closest, with
//   options.closest_features; asking a source without features throws std::invalid_argument); optionally
//   bool range(i, double* lo, double* hi) (SourceHasRange). Returns false when options.interrupter stopped it (polled
//   per 64 bricks while sorting, per 16 while filling, and per chunk).
// `window` streams only segments [window.first, window.last] of the field, so one run can deliver its near field from
// one source and the rest from another: a closed window never marks a segment last; an open one (last = kOpen)
// starting past 0 marks its final segment last, and when nothing lies in it, delivers an empty segment window.first
// marked complete and last (the end of the stream). A segment can also come from several sources, one after the
// other in (z, y, x) order (SegmentWindow::continued on all but the last; or the last source holds the earlier
// ones' bricks first, SegmentWindow::delivered); its stats add up in one entry.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/brick.h"
#include "core/field/field_run.h"
#include "core/first_touch.h"
#include "core/grid.h"
#include "core/interrupter.h"

namespace distband::separable_internal {

template <typename Source, typename = void>
struct SourceHasFeatures : std::false_type {};
template <typename Source>
struct SourceHasFeatures<Source, std::enable_if_t<Source::kHasFeatures>> : std::true_type {};

/// Whether `Source` has `bool range(i, double* lo, double* hi)`: the least and greatest |distance| (voxels) of the
/// voxels brick i delivers, false when it delivers none — how bricks are sorted into segments without a square root
/// per voxel (the distances must be value()'s, so that the segments are the same).
template <typename Source>
inline constexpr bool SourceHasRange = requires(const Source& s, double* d) {
  { s.range(size_t{0}, d, d) } -> std::same_as<bool>;
};

/// The brick list of a whole-grid source: every brick of the grid, in (z, y, x) order.
struct WholeGridBricks {
  const Grid& grid;
  size_t count() const { return size_t(grid.brickCount()); }
  Coord origin(size_t b) const { return grid.brickOrigin(int64_t(b)); }
};

/// The segments emitSegments delivers (see the contract above).
struct SegmentWindow {
  static constexpr int kOpen = std::numeric_limits<int>::max();
  int first = 0;
  int last = kOpen;
  /// More bricks of segment `last` (a closed window) follow from another source: its final chunk is not marked
  /// complete, and an empty one is not delivered.
  bool continued = false;
  /// The source's first `delivered` bricks have delivered their voxels of segment `first` already (a continued
  /// segment): they are not delivered in it again.
  size_t delivered = 0;
};

/// Streams `source` (see the contract above). False when interrupted.
template <typename Source>
bool emitSegments(const Grid& grid, const FieldRunOptions& options, const Source& source, FieldRunResult* result,
                  const SegmentCallback& on_segment, SegmentWindow window = {}) {
  using Clock = std::chrono::steady_clock;
  const Interrupter* interrupter = options.interrupter;
  const double h = grid.voxelSize();
  const bool closest = options.closest_features;
  if (closest && !SourceHasFeatures<Source>::value)
    throw std::invalid_argument("closest features: this algorithm does not track them (use the band)");
  // |distance| in voxels, and its segment: (i L, (i + 1) L], segment 0 including 0 (one segment when L = 0).
  const double length = options.segment_length_world > 0 ? options.segment_length_world / h : 0;
  auto segmentOf = [&](double d) { return length > 0 && d > length ? int(std::ceil(d / length)) - 1 : 0; };
  constexpr int kNone = std::numeric_limits<int>::max();
  // Each brick's segment range (kNone: nothing delivered), then the bricks of every segment in (z, y, x) order.
  const size_t bricks = source.count();
  std::vector<int> first(bricks), last(bricks);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, bricks, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t b = r.begin(); b != r.end(); ++b) {
      if ((b & 63) == 0 && isInterrupted(interrupter)) return;
      int lo = kNone, hi = -1;
      if constexpr (SourceHasRange<Source>) {
        if (length > 0) {  // one segment: the loop below stops at the first voxel delivered
          double d_lo, d_hi;
          if (source.range(b, &d_lo, &d_hi)) {
            // Every segment from the nearest voxel's to the farthest's: one may hold none of its voxels (the fill
            // below drops a brick without any), but no segment is missed.
            lo = std::max(segmentOf(d_lo), window.first);
            hi = std::min(segmentOf(d_hi), window.last);
            if (lo > hi) lo = kNone, hi = -1;
          }
          first[b] = lo;
          last[b] = hi;
          continue;
        }
      }
      const Coord origin = source.origin(b);
      for (int off = 0; off < kBrickVoxels; ++off) {
        double d;
        if (!source.value(b, off, origin + brickLocal(off), &d)) continue;
        const int s = segmentOf(std::abs(d));
        if (s < window.first || s > window.last) continue;
        lo = std::min(lo, s);
        hi = std::max(hi, s);
        if (length == 0 || (lo == window.first && hi == window.last)) break;  // nothing more to learn
      }
      first[b] = lo;
      last[b] = hi;
    }
  });
  if (isInterrupted(interrupter)) return false;
  // One past the final segment delivered: at least window.first + 1 (an empty first segment when nothing is in it).
  int segments = window.first + 1;
  for (int hi : last) segments = std::max(segments, hi + 1);
  if (window.last != SegmentWindow::kOpen) segments = std::min(segments, window.last + 1);
  std::vector<std::vector<uint32_t>> by_segment(static_cast<size_t>(segments));
  for (size_t b = 0; b < bricks; ++b)
    for (int s = first[b]; s <= last[b]; ++s)
      if (s != window.first || b >= window.delivered) by_segment[size_t(s)].push_back(uint32_t(b));
  const bool marks_last = window.last == SegmentWindow::kOpen;
  std::vector<int>().swap(first);
  std::vector<int>().swap(last);

  // Without chunking a segment is built in one piece, where it is delivered: no second copy of its bricks.
  const size_t per_chunk =
      options.max_chunk_bricks ? std::min<size_t>(options.max_chunk_bricks, 8192) : std::numeric_limits<size_t>::max();
  for (int s = window.first; s < segments; ++s) {
    const auto ts = Clock::now();
    SegmentStats stats;
    stats.index = s;
    stats.lower_world = length > 0 ? s * length * h : 0;
    stats.upper_world = std::min(length > 0 ? (s + 1) * length * h : std::numeric_limits<double>::infinity(),
                                 options.limit_world);
    const std::vector<uint32_t>& list = by_segment[size_t(s)];
    for (size_t c0 = 0; c0 < list.size() || c0 == 0;) {
      if (isInterrupted(interrupter)) return false;
      const size_t c1 = list.size() - c0 <= per_chunk ? list.size() : c0 + per_chunk;
      std::vector<Brick> part;
      appendUnsetBricks(part, c1 - c0);
      tbb::parallel_for(tbb::blocked_range<size_t>(c0, c1, 16), [&](const tbb::blocked_range<size_t>& r) {
        if (isInterrupted(interrupter)) return;
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const size_t b = list[i];
          Brick& brick = part[i - c0];
          brick.origin = source.origin(b);
          if (closest) brick.closest.assign(kBrickVoxels, -1);
          for (int off = 0; off < kBrickVoxels; ++off) {
            double d;
            const Coord c = brick.origin + brickLocal(off);
            if (!source.value(b, off, c, &d) || segmentOf(std::abs(d)) != s) {
              brick.values[off] = 0;  // the bricks were made without values (appendUnsetBricks)
              continue;
            }
            brick.values[off] = float(d * h);
            brick.mask.set(off);
            if constexpr (SourceHasFeatures<Source>::value)
              if (closest) brick.closest[off] = source.feature(b, off, c);
          }
        }
      });
      if (isInterrupted(interrupter)) return false;
      // A brick spanning segments s-1..s+1 may hold none of segment s: only bricks with voxels are delivered.
      part.erase(std::remove_if(part.begin(), part.end(), [](const Brick& b) { return b.mask.empty(); }), part.end());
      for (const Brick& b : part) stats.voxels += b.mask.count();
      stats.bricks += int64_t(part.size());
      const bool done = c1 >= list.size();
      const bool continued = done && window.continued && s == window.last;
      SegmentBricks p;
      p.index = s;
      p.lower_world = stats.lower_world;
      p.upper_world = stats.upper_world;
      p.complete = done && !continued;
      p.last = done && s + 1 == segments && marks_last;
      p.bricks = std::move(part);
      if (on_segment && !(continued && p.bricks.empty())) on_segment(std::move(p));
      if (done) break;
      c0 = c1;
    }
    std::vector<uint32_t>().swap(by_segment[size_t(s)]);
    stats.seconds = std::chrono::duration<double>(Clock::now() - ts).count();
    result->voxels += stats.voxels;
    if (!result->segments.empty() && result->segments.back().index == s) {  // continued from another source
      SegmentStats& into = result->segments.back();
      into.voxels += stats.voxels;
      into.bricks += stats.bricks;
      into.seconds += stats.seconds;
    } else {
      result->segments.push_back(stats);
    }
  }
  return true;
}

}  // namespace distband::separable_internal
