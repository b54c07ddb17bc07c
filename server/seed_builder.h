// Seed building: the Seeds of a resolved query (point, volume or mesh source on the query's grid).
// Contract: compute work — call it on the compute thread inside the shared arena (mesh seeds use TBB).
// Returns "" or the seed source's error (e.g. a volume with no outside voxel for a signed field), which the
// caller reports as INVALID_ARGUMENT. `seconds` receives the elapsed time. Thread-safe.
#pragma once

#include <string>

#include "core/interrupter.h"
#include "core/seeds.h"
#include "server/request_validation.h"

namespace distband {

/// Builds the seeds of a resolved query, polling `interrupter` (may be null) throughout. "" on success, otherwise
/// why not ("interrupted" when the interrupter tripped).
std::string buildSeeds(const ResolvedQuery& query, Seeds* seeds, const Interrupter* interrupter = nullptr);

}  // namespace distband
