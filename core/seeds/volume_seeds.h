// Volume seeds: distances from a dense uint8 mask (nonzero = seed) defined on the grid's voxels.
// Contract: mask has grid.voxelCount() bytes, x-fastest ([z][y][x] in C order, like a .npy of shape (Z,Y,X)).
//   unsigned: distance from each voxel centre to the nearest nonzero voxel centre, as scipy's
//             distance_transform_edt(mask == 0) * voxel_size; 0 on the mask.
//   signed:   outside (mask == 0): +distance to the nearest mask voxel; inside: -distance to the nearest
//             non-mask voxel, i.e. edt(mask == 0) - edt(mask != 0).
// Returns kInvalidArgument for a size mismatch, an empty mask, or (signed) a mask with no outside voxel,
// kResourceExhausted for more boundary voxels than the engine has site ids, and the interrupter's status when it
// (polled every z-slice) stopped the work.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/grid.h"
#include "core/interrupter.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

namespace distband {

/// The mask's own precondition, shared by the band's seeds and the separable EDT: OK or kInvalidArgument saying why no
/// field exists (an empty mask; signed: a mask with no zero voxel). O(mask) with an early exit.
Status checkSeedMask(const std::vector<uint8_t>& mask, bool signed_distance);

Status makeVolumeSeeds(const Grid& grid, const std::vector<uint8_t>& mask, bool signed_distance, Seeds* out,
                            const Interrupter* interrupter = nullptr);

}  // namespace distband
