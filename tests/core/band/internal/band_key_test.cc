// Tests for core/band/internal/band_key.h: the key's order (distance first, then the lower site), its fields, VoxelBits.
#include "core/band/internal/band_key.h"

#include <atomic>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

namespace distband::band_internal {
namespace {

TEST(BandKey, FieldsRoundTrip) {
  const uint64_t k = packKey(12.25f, 17, 123456);
  EXPECT_EQ(keyDist2(k), 12.25f);
  EXPECT_EQ(keySite(k), 123456u);
  EXPECT_EQ(keyDir(k), 17u);
  const uint64_t top = packKey(0.0f, kNoDirection, kMaxSites - 1);
  EXPECT_EQ(keySite(top), kMaxSites - 1);
  EXPECT_EQ(keyDir(top), kNoDirection);
  EXPECT_EQ(toKeySite(kNoSite), kNoSiteKey);
  EXPECT_EQ(toKeySite(5), 5u);
}

TEST(BandKey, DistanceDominatesSiteAndDirection) {
  // A smaller distance wins whatever the sites and directions, including the smallest float step.
  const float d = 9.0f, next = std::nextafter(d, 100.0f);
  EXPECT_LT(packKey(d, kNoDirection, kMaxSites - 1), packKey(next, 0, 0));
  EXPECT_LT(packKey(0.0f, 31, kNoSiteKey), packKey(1e-30f, 0, 0));
  EXPECT_LT(packKey(1e30f, 31, kNoSiteKey), kUntouched);
  // Positive floats order like their bits across exponents.
  const float values[] = {0.0f, 1e-20f, 0.5f, 1.0f, 2.0f, 3.0f, 1e6f, 3e38f};
  for (size_t i = 1; i < std::size(values); ++i)
    EXPECT_LT(packKey(values[i - 1], 0, 7), packKey(values[i], 0, 7)) << values[i];
}

TEST(BandKey, TiesGoToTheLowerSiteWhateverTheDirection) {
  EXPECT_LT(packKey(4.0f, 31, 10), packKey(4.0f, 0, 11));
  EXPECT_LT(packKey(4.0f, 3, 10), packKey(4.0f, 5, 10));  // same site: only the direction differs (either is fine)
  EXPECT_EQ(keySite(std::min(packKey(4.0f, 31, 10), packKey(4.0f, 0, 11))), 10u);
}

TEST(VoxelBits, SetTestClear) {
  VoxelBits bits;
  for (int i = 0; i < kBrickVoxels; ++i) EXPECT_FALSE(bits.test(i));
  EXPECT_TRUE(bits.set(0));
  EXPECT_TRUE(bits.set(511));
  EXPECT_TRUE(bits.set(64));
  EXPECT_FALSE(bits.set(64));  // already set
  EXPECT_TRUE(bits.test(0) && bits.test(64) && bits.test(511));
  EXPECT_FALSE(bits.test(1) || bits.test(63) || bits.test(65) || bits.test(510));
  bits.clear(64);
  EXPECT_FALSE(bits.test(64));
  EXPECT_TRUE(bits.test(0) && bits.test(511));
}

TEST(VoxelBits, ConcurrentSetsClaimEachBitOnce) {
  VoxelBits bits;
  std::atomic<int> claimed{0};
  tbb::parallel_for(0, 8 * kBrickVoxels, [&](int i) {
    if (bits.set(i % kBrickVoxels)) ++claimed;
  });
  EXPECT_EQ(claimed.load(), kBrickVoxels);
  for (int i = 0; i < kBrickVoxels; ++i) EXPECT_TRUE(bits.test(i));
}

}  // namespace
}  // namespace distband::band_internal
