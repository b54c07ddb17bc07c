// The engine's public entry points (see engine.h for the contract and docs/algorithm.md for the method): option
// checks and defaults, and computeDistanceField, which runs an engine::BandRun (core/engine/band_run.h) in the
// requested TBB arena. The engine's parts live in core/engine/: band_key.h (the per-voxel key), brick_table (sparse
// brick storage), link_table (the stencil's links), propagation, second_ring, emission, band_run (the segment loop).
#include "core/engine.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>

#include "core/engine/band_run.h"
#include "core/thread_arena.h"

namespace distband {

std::string_view modeName(PropagationMode mode) { return mode == PropagationMode::kPaper ? "paper" : "exact"; }

bool parseMode(std::string_view name, PropagationMode* mode) {
  if (name == "paper") *mode = PropagationMode::kPaper;
  else if (name == "exact") *mode = PropagationMode::kExact;
  else return false;
  return true;
}

StencilKind defaultStencil(SiteKind kind) {
  return kind == SiteKind::kTriangle ? StencilKind::kFcc12 : StencilKind::kCubic26;
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

std::string validateOptions(const Grid& grid, const EngineOptions& o) {
  if (std::string e = grid.validate(); !e.empty()) return "grid: " + e;
  if (!(o.segment_length_world >= 0) || std::isinf(o.segment_length_world))
    return fmt::format("segment_length must be finite and >= 0 (got {})", o.segment_length_world);
  if (!(o.limit_world > 0)) return fmt::format("limit must be > 0 (got {})", o.limit_world);
  if (o.threads < 0 || o.threads > 4096) return fmt::format("threads must be in [0, 4096] (got {})", o.threads);
  if (std::isnan(o.lifespan_alpha)) return "lifespan_alpha must not be NaN";
  if (o.lifespan_margin > 1000) return "lifespan_margin must be <= 1000";
  if (o.segment_length_world > 0 && std::isfinite(o.limit_world) &&
      o.limit_world / o.segment_length_world > 100000)
    return "limit / segment_length must be <= 100000 segments";
  return {};
}

namespace {

EngineResult runEngine(const Grid& grid, const Seeds& seeds, const EngineOptions& options,
                       const SegmentCallback& on_segment, std::vector<BandVoxel>* owned_band) {
  if (std::string e = validateOptions(grid, options); !e.empty()) throw std::invalid_argument(e);
  if (seeds.region && seeds.region->size() != size_t(grid.voxelCount()))
    throw std::invalid_argument("seeds.region must hold one label per grid voxel");
  EngineResult result;
  auto body = [&] {
    std::optional<engine::BandRun> run;
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

EngineResult computeDistanceField(const Grid& grid, const Seeds& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment) {
  return runEngine(grid, seeds, options, on_segment, nullptr);
}

EngineResult computeDistanceField(const Grid& grid, Seeds&& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment) {
  Seeds owned = std::move(seeds);
  return runEngine(grid, owned, options, on_segment, &owned.band);
}

}  // namespace distband
