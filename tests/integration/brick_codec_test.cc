// The brick wire codec (proto/brick_codec.h): float16 conversion against the compiler's _Float16 as an oracle,
// encode/decode round trips, and rejection of malformed bricks from an untrusted peer.
#include <bit>
#include <cmath>
#include <cstring>
#include <random>

#include <gtest/gtest.h>

#include "proto/brick_codec.h"

namespace distband {
namespace {

TEST(BrickCodecTest, HalfToFloatMatchesTheCompilerForEveryHalf) {
  for (uint32_t h = 0; h < 65536; ++h) {
    _Float16 oracle;
    const uint16_t bits = uint16_t(h);
    std::memcpy(&oracle, &bits, 2);
    const float want = float(oracle), got = halfToFloat(bits);
    if (std::isnan(want)) {
      EXPECT_TRUE(std::isnan(got)) << h;
    } else {
      ASSERT_EQ(std::bit_cast<uint32_t>(got), std::bit_cast<uint32_t>(want)) << "half 0x" << std::hex << h;
    }
  }
}

TEST(BrickCodecTest, FloatToHalfRoundsLikeTheCompiler) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint32_t> any;
  std::vector<float> samples = {0.0f, -0.0f, 1.0f, 65504.0f, 65519.99f, 65520.0f, 1e-8f, 2.98e-8f, 6.1e-5f,
                                std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  for (int i = 0; i < 2000000; ++i) samples.push_back(std::bit_cast<float>(any(rng)));
  // Exact ties between neighbouring halves (round to even).
  for (uint32_t h = 0; h < 0x7bff; ++h) {
    _Float16 a, b;
    uint16_t ha = uint16_t(h), hb = uint16_t(h + 1);
    std::memcpy(&a, &ha, 2);
    std::memcpy(&b, &hb, 2);
    samples.push_back((float(a) + float(b)) / 2);
  }
  for (float f : samples) {
    if (std::isnan(f)) {
      EXPECT_TRUE(std::isnan(halfToFloat(floatToHalf(f))));
      continue;
    }
    const _Float16 oracle = static_cast<_Float16>(f);
    uint16_t want;
    std::memcpy(&want, &oracle, 2);
    ASSERT_EQ(floatToHalf(f), want) << "float " << f << " (0x" << std::hex << std::bit_cast<uint32_t>(f) << ")";
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
    ASSERT_EQ(decodeBrick(data, enc, &out), "");
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

TEST(BrickCodecTest, MalformedBricksAreRejected) {
  Brick b;
  b.mask.set(5);
  b.values[5] = 1.5f;
  v1::BrickData good;
  encodeBrick(b, v1::BRICK_ENCODING_FLOAT32, &good);
  Brick out;
  v1::BrickData d = good;
  d.set_mask(std::string(63, '\0'));
  EXPECT_NE(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out).find("mask"), std::string::npos);
  d = good;
  d.set_values(std::string(8, '\0'));
  EXPECT_NE(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out).find("value bytes"), std::string::npos);
  d = good;
  d.set_x(3);
  EXPECT_NE(decodeBrick(d, v1::BRICK_ENCODING_FLOAT32, &out).find("multiple of 8"), std::string::npos);
  EXPECT_NE(decodeBrick(good, v1::BRICK_ENCODING_FLOAT16, &out), "");  // 4 bytes where 2 are due
}

}  // namespace
}  // namespace distband
