#include "proto/brick_codec.h"

#include <bit>
#include <cstring>

#include <fmt/format.h>

namespace distband {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian; add byte swaps");

size_t bytesPerValue(v1::BrickEncoding encoding) { return encoding == v1::BRICK_ENCODING_FLOAT16 ? 2 : 4; }

uint16_t floatToHalf(float value) {
  const uint32_t f = std::bit_cast<uint32_t>(value);
  const uint32_t sign = (f >> 16) & 0x8000u;
  const uint32_t abs = f & 0x7fffffffu;
  if (abs >= 0x7f800000u) {  // inf or NaN
    return uint16_t(sign | 0x7c00u | (abs > 0x7f800000u ? 0x200u | ((abs >> 13) & 0x3ffu) : 0u));
  }
  if (abs >= 0x477ff000u) return uint16_t(sign | 0x7c00u);  // rounds to >= 65520: overflow to infinity
  if (abs < 0x38800000u) {                                  // below the smallest normal half: subnormal or 0
    if (abs < 0x33000000u) return uint16_t(sign);          // < 2^-25 rounds to 0
    const uint32_t mant = (abs & 0x7fffffu) | 0x800000u;
    const int shift = 126 - int(abs >> 23);                 // 14..24
    const uint32_t half = mant >> shift;
    const uint32_t rem = mant & ((1u << shift) - 1);
    const uint32_t mid = 1u << (shift - 1);
    const uint32_t rounded = half + ((rem > mid || (rem == mid && (half & 1))) ? 1 : 0);
    return uint16_t(sign | rounded);
  }
  // Normal: rebias exponent (127 -> 15) and round the 23-bit mantissa to 10 bits, nearest even.
  const uint32_t base = abs - 0x38000000u;  // exponent - 112
  const uint32_t half = base >> 13;
  const uint32_t rem = base & 0x1fffu;
  const uint32_t rounded = half + ((rem > 0x1000u || (rem == 0x1000u && (half & 1))) ? 1 : 0);
  return uint16_t(sign | rounded);
}

float halfToFloat(uint16_t h) {
  const uint32_t sign = uint32_t(h & 0x8000u) << 16;
  const uint32_t exp = (h >> 10) & 0x1fu;
  const uint32_t mant = h & 0x3ffu;
  uint32_t f;
  if (exp == 0) {
    if (mant == 0) {
      f = sign;
    } else {  // subnormal: value = mant * 2^-24
      const float v = float(mant) * 5.9604644775390625e-8f;
      return sign ? -v : v;
    }
  } else if (exp == 31) {
    f = sign | 0x7f800000u | (mant << 13);
  } else {
    f = sign | ((exp + 112) << 23) | (mant << 13);
  }
  return std::bit_cast<float>(f);
}

size_t bytesPerClosest(v1::ClosestFeature closest) {
  switch (closest) {
    case v1::CLOSEST_FEATURE_TRIANGLE:
    case v1::CLOSEST_FEATURE_POINT:
    case v1::CLOSEST_FEATURE_LABEL:
      return 4;
    case v1::CLOSEST_FEATURE_VOXEL: return 8;
    default: return 0;
  }
}

void encodeBrick(const Brick& brick, v1::BrickEncoding encoding, v1::BrickData* out, v1::ClosestFeature closest) {
  out->set_x(brick.origin.x);
  out->set_y(brick.origin.y);
  out->set_z(brick.origin.z);
  out->set_mask(reinterpret_cast<const char*>(brick.mask.words.data()), 64);
  const size_t bpv = bytesPerValue(encoding);
  std::string* values = out->mutable_values();
  values->resize(size_t(brick.mask.count()) * bpv);
  char* dst = values->data();
  for (int w = 0; w < kBrickVoxels / 64; ++w) {
    uint64_t bits = brick.mask.words[w];
    while (bits) {
      const int i = w * 64 + std::countr_zero(bits);
      bits &= bits - 1;
      if (bpv == 4) {
        std::memcpy(dst, &brick.values[i], 4);
      } else {
        const uint16_t h = floatToHalf(brick.values[i]);
        std::memcpy(dst, &h, 2);
      }
      dst += bpv;
    }
  }
  const size_t bpc = bytesPerClosest(closest);
  if (bpc == 0 || brick.closest.size() != size_t(kBrickVoxels)) return;
  std::string* ids = out->mutable_closest();
  ids->resize(size_t(brick.mask.count()) * bpc);
  char* at = ids->data();
  for (int w = 0; w < kBrickVoxels / 64; ++w)
    for (uint64_t bits = brick.mask.words[w]; bits; bits &= bits - 1) {
      const int64_t id = brick.closest[size_t(w * 64 + std::countr_zero(bits))];
      if (bpc == 8) {
        std::memcpy(at, &id, 8);
      } else {
        const int32_t id32 = int32_t(id);
        std::memcpy(at, &id32, 4);
      }
      at += bpc;
    }
}

Status decodeBrick(const v1::BrickData& data, v1::BrickEncoding encoding, Brick* out, v1::ClosestFeature closest) {
  if (data.mask().size() != 64)
    return Status::InvalidArgument(fmt::format("brick mask has {} bytes, expected 64", data.mask().size()));
  if ((data.x() | data.y() | data.z()) & (kBrickSize - 1))
    return Status::InvalidArgument(
        fmt::format("brick origin ({}, {}, {}) is not a multiple of 8", data.x(), data.y(), data.z()));
  Brick b;
  b.origin = {data.x(), data.y(), data.z()};
  std::memcpy(b.mask.words.data(), data.mask().data(), 64);
  const size_t bpv = bytesPerValue(encoding);
  const size_t expected = size_t(b.mask.count()) * bpv;
  if (data.values().size() != expected)
    return Status::InvalidArgument(fmt::format("brick at ({}, {}, {}) has {} value bytes, its mask needs {}", data.x(),
                                               data.y(), data.z(), data.values().size(), expected));
  const char* src = data.values().data();
  for (int w = 0; w < kBrickVoxels / 64; ++w) {
    uint64_t bits = b.mask.words[w];
    while (bits) {
      const int i = w * 64 + std::countr_zero(bits);
      bits &= bits - 1;
      if (bpv == 4) {
        std::memcpy(&b.values[i], src, 4);
      } else {
        uint16_t h;
        std::memcpy(&h, src, 2);
        b.values[i] = halfToFloat(h);
      }
      src += bpv;
    }
  }
  if (const size_t bpc = bytesPerClosest(closest); bpc > 0) {
    const size_t ids = size_t(b.mask.count()) * bpc;
    if (data.closest().size() != ids)
      return Status::InvalidArgument(
          fmt::format("brick at ({}, {}, {}) has {} closest-feature bytes, its mask needs {}", data.x(), data.y(),
                      data.z(), data.closest().size(), ids));
    b.closest.assign(kBrickVoxels, -1);
    const char* at = data.closest().data();
    for (int w = 0; w < kBrickVoxels / 64; ++w)
      for (uint64_t bits = b.mask.words[w]; bits; bits &= bits - 1) {
        int64_t id;
        if (bpc == 8) {
          std::memcpy(&id, at, 8);
        } else {
          int32_t id32;
          std::memcpy(&id32, at, 4);
          id = closest == v1::CLOSEST_FEATURE_LABEL ? int64_t(uint32_t(id32)) : int64_t(id32);  // labels: uint32
        }
        b.closest[size_t(w * 64 + std::countr_zero(bits))] = id;
        at += bpc;
      }
  }
  *out = std::move(b);
  return Status::Ok();
}

}  // namespace distband
