#include "core/planned_field.h"

#include <stdexcept>
#include <utility>

#include "core/separable_edt.h"
#include "core/separable_points.h"

namespace distband {

EngineResult computePlannedField(const FieldPlan& plan, const Grid& grid, Seeds seeds, const std::vector<uint8_t>* mask,
                                 const EngineOptions& options, const SegmentCallback& on_segment) {
  if (plan.algorithm == FieldAlgorithm::kSeparable) {
    switch (plan.seeds) {
      case SeedKind::kVolume:
        if (!mask) throw std::invalid_argument("a separable volume plan needs the seed volume");
        return computeSeparableVolumeField(grid, *mask, plan.inside_negative, options, on_segment);
      case SeedKind::kPoints: return computeSeparablePointField(grid, seeds, options, on_segment);
      case SeedKind::kMesh: throw std::invalid_argument("meshes have no separable plan");
    }
  }
  return computeDistanceField(grid, std::move(seeds), options, on_segment);
}

}  // namespace distband
