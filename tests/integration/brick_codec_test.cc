// The brick wire codec (proto/brick_codec.h): float16 conversion against IEEE 754's definition as an oracle,
// encode/decode round trips, and rejection of malformed bricks from an untrusted peer.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "proto/brick_codec.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

// The oracle is IEEE 754 binary16 written out from its definition, in double (exact for every half): no compiler
// half type, which GCC has (_Float16) but clang 14 on x86-64 only with compiler-rt's builtins linked.
double exactHalf(uint16_t bits) {
  const int sign = bits >> 15, exponent = (bits >> 10) & 0x1f, mantissa = bits & 0x3ff;
  double magnitude;
  if (exponent == 0) {
    magnitude = std::ldexp(double(mantissa), -24);  // subnormal: mantissa x 2^-24
  } else if (exponent == 31) {
    magnitude = mantissa == 0 ? HUGE_VAL : std::nan("");
  } else {
    magnitude = std::ldexp(double(1024 + mantissa), exponent - 25);
  }
  return sign ? -magnitude : magnitude;
}

// Round to nearest, ties to the even half; beyond the largest half by half an ulp (65520) or more: infinity.
uint16_t nearestHalf(float f) {
  static const std::vector<double> positive = [] {  // every finite positive half (and +0), ascending
    std::vector<double> v;
    for (uint16_t h = 0; h <= 0x7bff; ++h) v.push_back(exactHalf(h));
    return v;
  }();
  const uint16_t sign = std::signbit(f) ? 0x8000 : 0;
  const double x = std::fabs(double(f));
  if (x >= 65520.0) return sign | 0x7c00;
  if (x >= 65504.0) return sign | 0x7bff;
  const auto hi = std::lower_bound(positive.begin(), positive.end(), x);
  if (*hi == x) return sign | uint16_t(hi - positive.begin());
  const uint16_t upper = uint16_t(hi - positive.begin()), lower = uint16_t(upper - 1);
  const double below = x - positive[lower], above = positive[upper] - x;
  if (below < above) return sign | lower;
  if (above < below) return sign | upper;
  return sign | ((lower & 1) == 0 ? lower : upper);
}

TEST(BrickCodecTest, HalfToFloatIsExactForEveryHalf) {
  for (uint32_t h = 0; h < 65536; ++h) {
    const uint16_t bits = uint16_t(h);
    const double want = exactHalf(bits);
    const float got = halfToFloat(bits);
    if (std::isnan(want)) {
      EXPECT_TRUE(std::isnan(got)) << h;
    } else {
      ASSERT_EQ(double(got), want) << "half 0x" << std::hex << h;
      ASSERT_EQ(std::signbit(got), std::signbit(want)) << "half 0x" << std::hex << h;
    }
  }
}

TEST(BrickCodecTest, FloatToHalfRoundsToNearestEven) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint32_t> any;
  std::vector<float> samples = {0.0f, -0.0f, 1.0f, 65504.0f, 65519.99f, 65520.0f, 1e-8f, 2.98e-8f, 6.1e-5f,
                                std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  for (int i = 0; i < 2000000; ++i) samples.push_back(std::bit_cast<float>(any(rng)));
  // Exact ties between neighbouring halves (round to even), and the values just beside them.
  for (uint16_t h = 0; h < 0x7bff; ++h) {
    const float tie = float((exactHalf(h) + exactHalf(uint16_t(h + 1))) / 2);
    samples.push_back(tie);
    samples.push_back(std::nextafter(tie, 0.0f));
    samples.push_back(std::nextafter(tie, HUGE_VALF));
  }
  for (float f : samples) {
    if (std::isnan(f)) {
      EXPECT_TRUE(std::isnan(halfToFloat(floatToHalf(f))));
      continue;
    }
    ASSERT_EQ(floatToHalf(f), nearestHalf(f)) << "float " << f << " (0x" << std::hex << std::bit_cast<uint32_t>(f)
                                              << ")";
  }
}

TEST(BrickCodecTest, RoundTripKeepsMaskedValuesOnly) {
  Brick b;
  b.origin = {8, -16, 24};
  std::mt19937 rng(3);
  for (int i = 0; i < kBrickVoxels; ++i) {
    b.values[i] = float(i) * 0.37f - 50.0f;
    if (rng() % 3 == 0) b.mask.set(i);
  }
  for (auto enc : {v1::BRICK_ENCODING_FLOAT32, v1::BRICK_ENCODING_FLOAT16}) {
    v1::BrickData data;
    encodeBrick(b, enc, &data);
    EXPECT_EQ(data.mask().size(), 64u);
    EXPECT_EQ(data.values().size(), size_t(b.mask.count()) * bytesPerValue(enc));
    Brick out;
    ASSERT_TRUE(IsOk(decodeBrick(data, enc, &out)));
    EXPECT_EQ(out.origin, b.origin);
    EXPECT_EQ(out.mask.words, b.mask.words);
    for (int i = 0; i < kBrickVoxels; ++i) {
      const float want = !b.mask.test(i) ? 0.0f
                         : enc == v1::BRICK_ENCODING_FLOAT32 ? b.values[i]
                                                             : halfToFloat(floatToHalf(b.values[i]));
      ASSERT_EQ(out.values[i], want) << i;
    }
  }
}

// Closest-feature ids ride beside the values: int32 for triangles and points, int64 for voxels, masked voxels only.
TEST(BrickCodecTest, ClosestFeatureIdsRoundTripAndTheirLengthIsChecked) {
  Brick b;
  b.origin = {0, 8, 16};
  b.closest.assign(kBrickVoxels, -1);
  for (int i = 0; i < kBrickVoxels; i += 3) {
    b.mask.set(i);
    b.values[i] = float(i);
    b.closest[size_t(i)] = int64_t(i) * 7919 + (int64_t(1) << 33);  // beyond 32 bits: only VOXEL keeps it
  }
  for (auto kind : {v1::CLOSEST_FEATURE_POINT, v1::CLOSEST_FEATURE_VOXEL}) {
    v1::BrickData data;
    encodeBrick(b, v1::BRICK_ENCODING_FLOAT32, &data, kind);
    EXPECT_EQ(data.closest().size(), size_t(b.mask.count()) * bytesPerClosest(kind));
    Brick out;
    ASSERT_TRUE(IsOk(decodeBrick(data, v1::BRICK_ENCODING_FLOAT32, &out, kind)));
    ASSERT_EQ(out.closest.size(), size_t(kBrickVoxels));
    for (int i = 0; i < kBrickVoxels; ++i) {
      const int64_t want = !b.mask.test(i)                      ? -1
                           : kind == v1::CLOSEST_FEATURE_VOXEL ? b.closest[size_t(i)]
                                                                : int64_t(int32_t(b.closest[size_t(i)]));
      EXPECT_EQ(out.closest[size_t(i)], want) << i;
    }
    data.mutable_closest()->pop_back();
    EXPECT_TRUE(IsError(decodeBrick(data, v1::BRICK_ENCODING_FLOAT32, &out, kind), Status::Code::kInvalidArgument,
                        "closest-feature bytes"));
  }
  v1::BrickData plain;
  encodeBrick(b, v1::BRICK_ENCODING_FLOAT32, &plain);
  EXPECT_TRUE(plain.closest().empty());
  Brick out;
  EXPECT_TRUE(IsError(decodeBrick(plain, v1::BRICK_ENCODING_FLOAT32, &out, v1::CLOSEST_FEATURE_TRIANGLE),
                      Status::Code::kInvalidArgument, "closest-feature bytes"));
}

TEST(BrickCodecTest, MalformedBricksAreRejected) {
  Brick b;
  b.mask.set(5);
  b.values[5] = 1.5f;
  v1::BrickData good;
  encodeBrick(b, v1::BRICK_ENCODING_FLOAT32, &good);
  Brick out;
  v1::BrickData d = good;
  d.set_mask(std::string(63, '\0'));
  EXPECT_TRUE(IsError(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out), Status::Code::kInvalidArgument, "mask"));
  d = good;
  d.set_values(std::string(8, '\0'));
  EXPECT_TRUE(IsError(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out), Status::Code::kInvalidArgument, "value bytes"));
  d = good;
  d.set_x(3);
  EXPECT_TRUE(
      IsError(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out), Status::Code::kInvalidArgument, "multiple of 8"));
  // 4 bytes where 2 are due
  EXPECT_TRUE(
      IsError(decodeBrick(good, v1::BRICK_ENCODING_FLOAT16, &out), Status::Code::kInvalidArgument, "value bytes"));
}

}  // namespace
}  // namespace distband
