// Fuzz target: decoding a BrickData (proto/brick_codec.h) from arbitrary bytes, as the client does with what a
// server sends. The first byte picks the encoding (bit 0) and the closest-feature kind (bits 1-2). A brick that
// decodes must re-encode to the same mask, values (float32) and closest-feature ids, and decode again equal.
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "distband/v1/distband.pb.h"
#include "proto/brick_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const auto encoding = data[0] & 1 ? distband::v1::BRICK_ENCODING_FLOAT16 : distband::v1::BRICK_ENCODING_FLOAT32;
  const auto closest = distband::v1::ClosestFeature((data[0] >> 1) & 3);
  distband::v1::BrickData wire;
  if (!wire.ParseFromArray(data + 1, int(size - 1))) return 0;
  distband::Brick brick;
  if (const distband::Status s = distband::decodeBrick(wire, encoding, &brick, closest); !s.ok()) {
    if (s.code() != distband::Status::Code::kInvalidArgument || s.message().empty()) __builtin_trap();
    return 0;
  }
  if (brick.origin.x % 8 || brick.origin.y % 8 || brick.origin.z % 8) __builtin_trap();
  if ((closest != distband::v1::CLOSEST_FEATURE_NONE) != (brick.closest.size() == size_t(distband::kBrickVoxels)))
    __builtin_trap();
  distband::v1::BrickData again;
  distband::encodeBrick(brick, distband::v1::BRICK_ENCODING_FLOAT32, &again, closest);
  distband::Brick round_trip;
  if (!distband::decodeBrick(again, distband::v1::BRICK_ENCODING_FLOAT32, &round_trip, closest).ok()) __builtin_trap();
  if (std::memcmp(&round_trip.mask, &brick.mask, sizeof brick.mask) != 0) __builtin_trap();
  for (int i = 0; i < distband::kBrickVoxels; ++i) {
    if (!brick.mask.test(i)) continue;
    if (std::memcmp(&round_trip.values[i], &brick.values[i], 4) != 0) __builtin_trap();
    if (!brick.closest.empty() && round_trip.closest[size_t(i)] != brick.closest[size_t(i)]) __builtin_trap();
  }
  return 0;
}
