// Volume seeds: what a seed or label volume (core/seeds/label_volume.h) on the grid's voxels is measured as, and the
// band's seeds of its seed field.
// Contract:
//   * VolumeMeasure says what is measured (the planner decides it, core/field/field_plan.h): the seed field, whose
//     seeds are the nonzero voxels —
//       unsigned: distance from each voxel centre to the nearest nonzero voxel centre, as scipy's
//                 distance_transform_edt(volume == 0, sampling=spacing); 0 on the seeds;
//       signed:   outside (label 0): +distance to the nearest seed; seeds: -distance to the nearest zero voxel,
//                 i.e. edt(volume == 0) - edt(volume != 0) —
//     or the multi-label EDT (seung-lab edt's edt::edt: a voxel of label L != 0 gets its distance to the nearest voxel
//     whose label differs from L, label 0 gets 0), which only the separable EDT computes
//     (core/separable/volume_edt.h). checkVolumeMeasure() says whether the field exists.
//   * makeVolumeSeeds(): the band's Seeds of the seed field (sites: the boundary voxels). The volume must have the
//     grid's dims. Returns kInvalidArgument for a size mismatch or checkVolumeMeasure's reasons, kResourceExhausted for
//     more boundary voxels than the engine has site ids, and the interrupter's status when it (polled every z-slice)
//     stopped the work.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/grid.h"
#include "core/interrupter.h"
#include "core/seeds/label_volume.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

/// Faces of a grid, as bits: the low (bit 2a) and high (bit 2a + 1) face along axis a (x, y, z).
inline constexpr uint8_t kAllFaces = 0x3F;

/// What a volume run measures (see the contract).
struct VolumeMeasure {
  bool labels = false;           ///< the multi-label EDT; false: the seed field
  bool inside_negative = false;  ///< seed field: seeds get -distance to the nearest zero voxel
  /// Multi-label EDT: the faces beyond which the outside is label 0 (the black border: kAllFaces; a tile of a grid
  /// keeps only the faces it shares with the grid).
  uint8_t black_border = 0;
};

/// OK when the field exists, else kInvalidArgument saying why: the seed field needs a nonzero voxel (and, signed, a
/// zero one); the multi-label EDT two different labels, a black border, or only label 0 (all distances 0). O(volume)
/// with an early exit; shared by the band's seeds and the separable EDT.
Status checkVolumeMeasure(const LabelVolume& volume, const VolumeMeasure& measure);

Status makeVolumeSeeds(const Grid& grid, const LabelVolume& volume, bool signed_distance, Seeds* out,
                       const Interrupter* interrupter = nullptr);

}  // namespace distband
