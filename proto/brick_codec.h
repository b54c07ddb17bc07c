// Brick codec: core Bricks <-> distband.v1.BrickData, the wire form shared by the server and the remote client.
// Contract:
//   * encodeBrick appends one BrickData holding the brick's masked voxels only: a 64-byte little-endian mask and
//     one value per set bit in increasing offset order, as float32 or float16 (round to nearest even).
//   * decodeBrick validates untrusted input (mask length, value byte count, origin alignment) and returns OK or
//     kInvalidArgument naming the problem; on success the brick's masked values are set and the others are 0.
//   * With a closest-feature kind (QueryHeader.closest_feature) BrickData.closest carries Brick::closest of the
//     masked voxels in the same order, int32 (TRIANGLE, POINT), uint32 (LABEL) or int64 (VOXEL) little-endian;
//     decodeBrick then requires it (byte count checked) and fills Brick::closest (-1 where the mask is clear).
//   * The protocol lives in proto/ because both sides need it; core/ stays free of Protobuf.
// Pure functions; thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/brick.h"
#include "core/status.h"
#include "distband/v1/distband.pb.h"

namespace distband {

/// Bytes per value of an encoding (FLOAT32 when UNSPECIFIED).
size_t bytesPerValue(v1::BrickEncoding encoding);

/// IEEE 754 binary32 -> binary16, round to nearest even; overflow -> infinity, NaN stays NaN.
uint16_t floatToHalf(float value);
float halfToFloat(uint16_t half);

/// Bytes per closest-feature id of a kind (0 for NONE).
size_t bytesPerClosest(v1::ClosestFeature closest);

/// Wire bytes a brick with `voxels` delivered voxels takes (values + mask + origin, approximately the tags).
inline size_t encodedBrickBytes(int voxels, v1::BrickEncoding encoding,
                                v1::ClosestFeature closest = v1::CLOSEST_FEATURE_NONE) {
  return size_t(voxels) * (bytesPerValue(encoding) + bytesPerClosest(closest)) + 64 + 24;
}

/// Appends `brick` (its masked voxels) to `out`.
void encodeBrick(const Brick& brick, v1::BrickEncoding encoding, v1::BrickData* out,
                 v1::ClosestFeature closest = v1::CLOSEST_FEATURE_NONE);

/// Decodes one BrickData: OK, or kInvalidArgument saying what is wrong with it.
Status decodeBrick(const v1::BrickData& data, v1::BrickEncoding encoding, Brick* out,
                   v1::ClosestFeature closest = v1::CLOSEST_FEATURE_NONE);

}  // namespace distband
