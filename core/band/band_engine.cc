// The band engine's public entry points (band_engine.h has the contract, docs/algorithm.md the method): option checks
// and defaults, and computeBandField, which runs a band_internal::BandRun in the requested TBB arena. The engine's
// parts live in core/band/internal/: band_key.h (the per-voxel key), brick_table (sparse brick storage), link_table
// (the stencil's links), propagation, second_ring, emission, band_run (the segment loop).
#include "core/band/band_engine.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>

#include <malloc.h>

#include <fmt/format.h>

#include "core/band/internal/band_run.h"
#include "core/thread_arena.h"

namespace distband {

std::string_view modeName(PropagationMode mode) { return mode == PropagationMode::kPaper ? "paper" : "exact"; }

bool parseMode(std::string_view name, PropagationMode* mode) {
  for (PropagationMode m : kPropagationModes)
    if (name == modeName(m)) return *mode = m, true;
  return false;
}

StencilKind defaultStencil(SiteKind kind, bool cubic_grid) {
  return kind == SiteKind::kTriangle && cubic_grid ? StencilKind::kFcc12 : StencilKind::kCubic26;
}

int defaultLifespanMargin(StencilKind stencil) {
  // The paper's t_min/t_max bounds hold for arrival times counted from the site; our clock starts at the initial
  // band, up to ~1 voxel (1–2 steps) off the site. See docs/algorithm.md and the lifespan tests.
  switch (stencil) {
    case StencilKind::kCubic6: return 3;
    case StencilKind::kCubic18: return 2;
    case StencilKind::kCubic26: return 2;
    case StencilKind::kFcc12: return 2;
  }
  return 2;
}

Status validateBandOptions(const Grid& grid, const BandOptions& o) {
  if (Status s = validateRunOptions(grid, o); !s.ok()) return s;
  if (std::isnan(o.lifespan_alpha)) return Status::InvalidArgument("lifespan_alpha must not be NaN");
  if (o.lifespan_margin > 1000) return Status::InvalidArgument("lifespan_margin must be <= 1000");
  return Status::Ok();
}

namespace {

// The engine's bricks and large lists are mapped on their own (BrickPool, MappedAllocator), so memory left free in
// malloc's heaps cannot hold them, as it held the bricks when they came from malloc: when the inputs' making left a
// sizeable amount there, it is handed back first rather than staying resident beside them (a 3.33 M-triangle mesh at
// 1024^3: ~100 MB free in the heap when the engine starts; peak RSS 588 MB without this, 551 MB before the pool).
// The trim keeps kGiveBackFreeHeap at the main heap's top (the free blocks below it, and other arenas' free blocks, it
// gives back whole): a batch command's heap grows in steps of that size on huge pages (the CLI's policy,
// client/batch_heap.h), untouched for the most part, and that step alone passes the threshold, so trimming to nothing
// gave its pages back every run.
constexpr size_t kGiveBackFreeHeap = size_t(64) << 20;

void giveBackFreeHeap() {
  if (::mallinfo2().fordblks >= kGiveBackFreeHeap) ::malloc_trim(kGiveBackFreeHeap);
}

FieldRunResult runEngine(const Grid& grid, const Seeds& seeds, const BandOptions& options,
                         const SegmentCallback& on_segment, BandVoxels* owned_band) {
  if (Status s = validateBandOptions(grid, options); !s.ok()) throw std::invalid_argument(s.message());
  if (seeds.region && seeds.region->size() != size_t(grid.voxelCount()))
    throw std::invalid_argument("seeds.region must hold one label per grid voxel");
  giveBackFreeHeap();
  FieldRunResult result;
  auto body = [&] {
    std::optional<band_internal::BandRun> run;
    run.emplace(grid, seeds, options, on_segment, owned_band);
    result = run->run();
    const auto t0 = std::chrono::steady_clock::now();
    run.reset();
    result.release_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace

FieldRunResult computeBandField(const Grid& grid, const Seeds& seeds, const BandOptions& options,
                                  const SegmentCallback& on_segment) {
  return runEngine(grid, seeds, options, on_segment, nullptr);
}

FieldRunResult computeBandField(const Grid& grid, Seeds&& seeds, const BandOptions& options,
                                  const SegmentCallback& on_segment) {
  Seeds owned = std::move(seeds);
  return runEngine(grid, owned, options, on_segment, &owned.band);
}

}  // namespace distband
