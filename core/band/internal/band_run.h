// BandRun: one engine run, segment by segment: the loop that drives propagation (propagation.h), the second-ring
// correction (second_ring.h) and emission (emission.h) over a shared BandState.
// Contract: built and run once by computeBandField (core/band/band_engine.cc), inside the run's TBB arena, after the
// options were validated. run() returns the run's result; the destructor frees the run's state.
#pragma once

#include <vector>

#include "core/band/band_engine.h"
#include "core/band/internal/band_state.h"

namespace distband::band_internal {

class BandRun {
 public:
  /// `owned_band`: seeds.band when the caller handed the seeds over, else null; freed as soon as the engine no longer
  /// reads it (after the insertion, or after the first step for an exact band, whose first step pushes from it).
  BandRun(const Grid& grid, const Seeds& seeds, const BandOptions& opt, const SegmentCallback& cb,
          BandVoxels* owned_band);
  ~BandRun();

  FieldRunResult run();

 private:
  BandState state_;
  const SegmentCallback& cb_;
  BandVoxels* owned_band_;
};

}  // namespace distband::band_internal
