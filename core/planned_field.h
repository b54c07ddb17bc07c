// computePlannedField: runs a FieldPlan's algorithm — the one place that maps a plan to its compute entry point, for
// the server's query jobs, `distband compute` and the benches.
// Contract: a seed volume's separable plan reads `mask` (the seed volume, x fastest, on `grid`) and ignores `seeds`;
// every other plan reads `seeds`, built for the plan (core/seeds/), which the band engine consumes. What each
// algorithm delivers, and how it streams, is its entry point's contract: core/engine.h (the band),
// core/separable_edt.h (volumes), core/separable_points.h (points). `options` are plan.engineOptions() plus the run's
// threads, interrupter and chunking. Throws what the entry points throw (std::invalid_argument for a broken
// precondition, e.g. a separable volume plan without a mask).
#pragma once

#include <cstdint>
#include <vector>

#include "core/engine.h"
#include "core/field_plan.h"
#include "core/grid.h"
#include "core/seeds.h"

namespace distband {

EngineResult computePlannedField(const FieldPlan& plan, const Grid& grid, Seeds seeds, const std::vector<uint8_t>* mask,
                                 const EngineOptions& options, const SegmentCallback& on_segment);

}  // namespace distband
