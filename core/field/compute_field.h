// Compute a planned field: the one place that maps a FieldPlan to what its algorithm consumes and to its entry point,
// for the server's query jobs, `distband compute` and the benches.
// Contract:
//   * buildFieldInputs() turns the request's seeds (SeedSource) into the plan's inputs: the volume itself for the
//     separable volume EDT (checked by checkVolumeMeasure), Seeds (core/seeds/) for every other plan — the band's
//     input, and the separable point EDT's. With `window` (a tile: a box of `grid`) the inputs are for the grid the
//     algorithm runs on, grid.window(*window): point sites stay in the whole grid's index space so a tile's values
//     equal the whole grid's; a volume must then cover the window. Mesh seeds poll `interrupter`. Returns OK,
//     kInvalidArgument naming what is wrong with the seeds (an empty mask, a signed volume without outside, ...),
//     or kCancelled / the interrupter's status when it stopped the build.
//   * computeField() runs the plan's algorithm on its inputs under the run contract (core/field/field_run.h); what
//     each algorithm adds is its entry point's contract: core/band/band_engine.h, core/separable/volume_edt.h,
//     core/separable/point_edt.h. `run` is plan.runOptions() plus the run's threads, interrupter and chunking. A signed
//     mesh field's result also says how its voxels were signed (FieldRunResult::sign_shares).
//     Throws std::invalid_argument for a broken precondition (inputs not built for this plan).
// Thread-safe; the inputs are moved in and freed as the algorithm allows.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/field/field_plan.h"
#include "core/field/field_run.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/label_volume.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

/// The seeds of a request as given; the one matching plan.seeds is read.
struct SeedSource {
  const std::vector<Vec3d>* points = nullptr;  ///< kPoints: world coordinates
  LabelVolume volume;                          ///< kVolume: on the grid the algorithm runs on
  const TriangleMesh* mesh = nullptr;          ///< kMesh: validated (core/mesh/triangle_mesh.h)
};

/// What the plan's algorithm consumes.
struct FieldInputs {
  Seeds seeds;         ///< the band's and the separable point EDT's input
  LabelVolume volume;  ///< the separable volume EDT's input; empty for every other plan
  /// The faces of the run's grid that are the whole grid's (VolumeMeasure's bits): a tile's window keeps the black
  /// border only there.
  uint8_t grid_faces = kAllFaces;
};

Status buildFieldInputs(const FieldPlan& plan, const Grid& grid, const VoxelBox* window, const SeedSource& source,
                        const Interrupter* interrupter, FieldInputs* out);

/// `grid`: the grid the algorithm runs on (a tile's window for a tile).
FieldRunResult computeField(const FieldPlan& plan, const Grid& grid, FieldInputs inputs, const FieldRunOptions& run,
                            const SegmentCallback& on_segment);

}  // namespace distband
