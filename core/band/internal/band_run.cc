#include "core/band/internal/band_run.h"

#include <chrono>
#include <stdexcept>

#include "core/band/internal/emission.h"
#include "core/band/internal/propagation.h"
#include "core/band/internal/second_ring.h"

namespace distband::band_internal {
namespace {

// With many competing sites the first site to reach a voxel (fewest steps) is often not its closest, and every
// later improvement is propagated again. Admitting offers in distance slices of this width (replaying the held-back
// ones when a slice's front empties) brings them in nearly nearest-first: about half the updates for meshes and
// volumes. With few sites there is little to gain and the replays would cost, so it starts at kBucketMinSites.
// Triangle sites (fcc12 by default) do best with wider slices: 5-10 % less time at 20- and 60-voxel bands than 4.
constexpr double kBucketVoxels = 4.0;
constexpr double kTriangleBucketVoxels = 8.0;
constexpr size_t kBucketMinSites = 256;

}  // namespace

BandRun::BandRun(const Grid& grid, const Seeds& seeds, const BandOptions& opt, const SegmentCallback& cb,
                 BandVoxels* owned_band)
    : state_(grid, seeds, opt), cb_(cb), owned_band_(owned_band) {}

BandRun::~BandRun() { releaseBricks(state_); }

FieldRunResult BandRun::run() {
  using Clock = std::chrono::steady_clock;
  BandState& s = state_;
  const auto t0 = Clock::now();
  FieldRunResult result;
  const bool correcting =
      s.opt.mode == PropagationMode::kExact && s.opt.second_ring.value_or(s.seeds.kind == SiteKind::kPoint);

  const bool segmented = s.segment_vox > 0;
  auto upperOf = [&](int i) {
    double u = segmented ? (i + 1) * s.segment_vox : INFINITY;
    return std::min(u, s.limit_vox);
  };
  // Exact mode only: the paper's band keeps the paper's order (slices would also delay voxels past a lifespan
  // counted from the segment start).
  const double bucket_vox =
      s.opt.mode != PropagationMode::kExact || s.seeds.siteCount() < kBucketMinSites ? 0.0
      : s.seeds.kind == SiteKind::kTriangle                                           ? kTriangleBucketVoxels
                                                                                      : kBucketVoxels;
  insertBand(s);
  const bool push_band = s.seeds.band_exact;  // first step from the band list, in segment 0 (below)
  FrontList front;
  auto releaseBand = [&] {
    if (owned_band_) BandVoxels().swap(*owned_band_);
  };
  if (!push_band) {
    releaseBand();
    gatherFront(s, front);
  }

  for (int seg = 0;; ++seg) {
    const auto ts = Clock::now();
    SegmentStats stats;
    stats.index = seg;
    const double lower = seg == 0 ? 0.0 : upperOf(seg - 1);
    const double upper = upperOf(seg);
    stats.lower_world = lower * s.grid.voxelSize();
    stats.upper_world = upper * s.grid.voxelSize();
    s.thr_is_limit = upper >= s.limit_vox;
    s.thr2 = std::isfinite(upper) ? float(upper * upper) : INFINITY;
    // Offers are admitted up to the current slice (the whole segment without buckets) plus the slack.
    double slice_upper = bucket_vox > 0 ? std::min(upper, lower + bucket_vox) : upper;
    auto admitUpTo = [&](double u) {
      // A slice whose admission would reach the limit's is the limit's: nothing beyond it is held back.
      const double limit_admit = s.limit_vox + kLimitSlackVoxels * s.slack_scale;
      const double admit_slack = kAdmitSlackVoxels * s.slack_scale;
      const bool at_limit = u >= s.limit_vox || u + admit_slack >= limit_admit;
      const double admit = at_limit ? limit_admit : u + admit_slack;
      s.admit2 = std::isfinite(admit) ? float(admit * admit) : INFINITY;
      s.defer = !at_limit;
      if (at_limit) slice_upper = upper;
    };
    admitUpTo(slice_upper);
    s.segment_start_step = s.step;
    s.lower_vox = lower;
    if (seg > 0 && s.lifespan.enabled) rearmLifespans(s);
    s.collect_dirty = false;
    // The outer boundary of the finished region seeds this segment: every offer held back, replayed with the site
    // it offered then (the voxel may hold a better one for itself now, but not for its neighbours).
    if (seg > 0) front = takeDeferred(s);
    if (seg == 0 && push_band && !s.stopping()) {
      ++s.step;
      ++stats.steps;
      if (s.opt.on_step) s.opt.on_step(s.step, s.seeds.band.size());
      // Its next front is ~40 % of the band (meshes at half-width 3 and 20).
      reserveNext(s, s.seeds.band.size() * 3 / 4);
      stepFromBand(s, owned_band_ != nullptr);
      releaseBand();
      gatherFront(s, front);
    }
    for (;;) {
      if (s.stopping()) {
        result.interrupted = true;
        break;
      }
      if (front.empty() && slice_upper < upper) {
        front = takeDeferred(s);
        if (front.empty()) {
          slice_upper = upper;  // nothing held back: the segment is done
        } else {
          slice_upper = std::min(upper, slice_upper + bucket_vox);
          admitUpTo(slice_upper);
          continue;
        }
      }
      if (front.empty()) {
        if (!correcting) break;
        front = correct(s, !s.collect_dirty);
        s.collect_dirty = true;
        if (front.empty()) break;
      }
      if (++s.step >= kMaxSteps) throw std::runtime_error("distband engine: step limit exceeded");
      ++stats.steps;
      if (s.opt.on_step) s.opt.on_step(s.step, front.size());
      step(s, front);
      gatherFront(s, front);
    }
    releaseFronts(s, front);
    if (result.interrupted) break;
    collectDeferred(s);  // false only when the run stops, which the next line sees
    if (s.stopping()) {
      result.interrupted = true;
      break;
    }
    stats.seconds = std::chrono::duration<double>(Clock::now() - ts).count();
    const bool last = emitSegment(s, cb_, seg, lower, upper, s.deferred.empty(), stats);
    if (s.stopping()) {
      result.interrupted = true;
      break;
    }
    s.frozen2 = s.thr2;
    result.voxels += stats.voxels;
    result.segments.push_back(stats);
    if (last) break;
  }
  result.steps = s.step;
  result.corrections = s.corrections;
  for (auto& tb : s.buffers) {
    result.updates += tb.updates;
    result.bricks_allocated += tb.bricks;
  }
  result.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return result;
}

}  // namespace distband::band_internal
