#include "server/seed_builder.h"

#include "core/seeds/mesh_seeds.h"
#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"

namespace distband {

std::string buildSeeds(const ResolvedQuery& q, Seeds* seeds, const Interrupter* interrupter) {
  switch (q.seed_kind) {
    case ResolvedQuery::SeedKind::kPoints:  // sites in the whole grid's coordinates: tiles stay bit-identical
      return makePointSeeds(q.grid, q.points, seeds, q.tile ? &q.tile->window : nullptr);
    case ResolvedQuery::SeedKind::kVolume:  // a tile's volume covers its window (checked by resolveQuery)
      return makeVolumeSeeds(q.engineGrid(), *q.asset->mask, q.plan.inside_negative, seeds, interrupter);
    case ResolvedQuery::SeedKind::kMesh: {
      MeshSeedOptions o = q.plan.meshSeedOptions(q.engineGrid());
      o.interrupter = interrupter;
      return makeMeshSeeds(q.engineGrid(), *q.asset->mesh, o, seeds);
    }
  }
  return "unknown seed kind";
}

}  // namespace distband
