#include "core/field/compute_field.h"

#include <stdexcept>
#include <utility>

#include "core/band/band_engine.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "core/separable/point_edt.h"
#include "core/separable/volume_edt.h"

namespace distband {

Status buildFieldInputs(const FieldPlan& plan, const Grid& grid, const VoxelBox* window, const SeedSource& source,
                        const Interrupter* interrupter, FieldInputs* out) {
  const Grid run_grid = window ? grid.window(*window) : grid;
  FieldInputs in;
  if (window) {
    in.grid_faces = 0;
    const int lo[3] = {window->min.x, window->min.y, window->min.z};
    const int hi[3] = {window->end().x, window->end().y, window->end().z};
    const int n[3] = {grid.dims().x, grid.dims().y, grid.dims().z};
    for (int a = 0; a < 3; ++a) in.grid_faces |= uint8_t((lo[a] == 0) << (2 * a) | (hi[a] == n[a]) << (2 * a + 1));
  }
  switch (plan.seeds) {
    case SeedKind::kPoints:
      if (!source.points) throw std::invalid_argument("buildFieldInputs: point seeds need their points");
      if (Status s = makePointSeeds(grid, *source.points, &in.seeds, window); !s.ok()) return s;
      break;
    case SeedKind::kVolume:
      if (!source.volume) throw std::invalid_argument("buildFieldInputs: a seed volume needs its volume");
      if (plan.algorithm == FieldAlgorithm::kSeparable) {  // the separable EDT reads the volume itself
        VolumeMeasure measure = plan.volumeMeasure();
        measure.black_border &= in.grid_faces;
        if (Status s = checkVolumeMeasure(source.volume, measure); !s.ok()) return s;
        in.volume = source.volume;
      } else if (Status s = makeVolumeSeeds(run_grid, source.volume, plan.inside_negative, &in.seeds, interrupter);
                 !s.ok()) {
        return s;
      }
      break;
    case SeedKind::kMesh: {
      if (!source.mesh) throw std::invalid_argument("buildFieldInputs: mesh seeds need the mesh");
      MeshSeedOptions o = plan.meshSeedOptions(run_grid);
      o.interrupter = interrupter;
      if (Status s = makeMeshSeeds(run_grid, *source.mesh, o, &in.seeds); !s.ok()) return s;
      break;
    }
  }
  *out = std::move(in);
  return Status::Ok();
}

FieldRunResult computeField(const FieldPlan& plan, const Grid& grid, FieldInputs inputs, const FieldRunOptions& run,
                            const SegmentCallback& on_segment) {
  if (plan.algorithm == FieldAlgorithm::kSeparable) {
    switch (plan.seeds) {
      case SeedKind::kVolume: {
        if (!inputs.volume) throw std::invalid_argument("computeField: a separable volume plan needs the volume");
        VolumeMeasure measure = plan.volumeMeasure();
        measure.black_border &= inputs.grid_faces;
        return computeSeparableVolumeField(grid, inputs.volume, measure, run, on_segment);
      }
      case SeedKind::kPoints: return computeSeparablePointField(grid, inputs.seeds, run, on_segment);
      case SeedKind::kMesh: throw std::invalid_argument("computeField: meshes have no separable plan");
    }
  }
  const std::function<SignShares()> shares = inputs.seeds.sign_shares;
  FieldRunResult result = computeBandField(grid, std::move(inputs.seeds), plan.bandOptions(run), on_segment);
  if (shares) result.sign_shares = shares();
  return result;
}

}  // namespace distband
