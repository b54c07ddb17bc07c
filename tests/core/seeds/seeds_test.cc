// Tests for core/seeds: point seeds (band, index-space sites, clipping, errors) and volume seeds (boundary
// sites, interior voxels, signed bands across the boundary, region labels, the sign callback, errors).
#include <cmath>
#include <limits>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "core/status.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

std::set<std::tuple<int, int, int>> bandSet(const Seeds& s) {
  std::set<std::tuple<int, int, int>> out;
  for (const BandVoxel& b : s.band) out.insert({b.voxel.x, b.voxel.y, b.voxel.z});
  return out;
}

TEST(PointSeedsTest, BandIsTheBlockAroundTheNearestVoxel) {
  const Grid g({1.0, -2.0, 0.5}, 0.5, {20, 20, 20});
  Seeds s;
  ASSERT_TRUE(IsOk(makePointSeeds(g, {{3.1, 1.4, 4.0}}, &s)));
  EXPECT_EQ(s.kind, SiteKind::kPoint);
  ASSERT_EQ(s.points.size(), 1u);
  // Index space: (world - origin) / h.
  EXPECT_DOUBLE_EQ(s.points[0].x, (3.1 - 1.0) / 0.5);
  EXPECT_DOUBLE_EQ(s.points[0].y, (1.4 + 2.0) / 0.5);
  EXPECT_DOUBLE_EQ(s.points[0].z, (4.0 - 0.5) / 0.5);
  EXPECT_EQ(s.band.size(), 27u);
  const auto band = bandSet(s);
  EXPECT_EQ(band.size(), 27u);
  // Nearest voxel of index (4.2, 6.8, 7.0) is (4, 7, 7).
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) EXPECT_TRUE(band.count({4 + dx, 7 + dy, 7 + dz}));
  for (const BandVoxel& b : s.band) EXPECT_EQ(b.site, 0u);
  EXPECT_EQ(s.region, nullptr);
  EXPECT_FALSE(s.sign);
  EXPECT_EQ(s.siteCount(), 1u);
}

TEST(PointSeedsTest, PointsOutsideTheGridSeedTheClampedCorner) {
  const Grid g({0, 0, 0}, 1.0, {8, 8, 8});
  Seeds s;
  ASSERT_TRUE(IsOk(makePointSeeds(g, {{-5.0, -5.0, -5.0}, {3.0, 3.0, 3.0}}, &s)));
  ASSERT_EQ(s.points.size(), 2u);
  EXPECT_DOUBLE_EQ(s.points[0].x, -5.0);  // the site stays where it is; only the band is clamped
  int site0 = 0, site1 = 0;
  for (const BandVoxel& b : s.band) {
    EXPECT_TRUE(g.contains(b.voxel));
    if (b.site == 0) {
      ++site0;
      EXPECT_LE(std::max({b.voxel.x, b.voxel.y, b.voxel.z}), 1);
    } else {
      EXPECT_EQ(b.site, 1u);
      ++site1;
    }
  }
  EXPECT_EQ(site0, 8);  // the 2x2x2 part of the 3^3 block that lies inside the grid
  EXPECT_EQ(site1, 27);
}

TEST(PointSeedsTest, Errors) {
  const Grid g({0, 0, 0}, 1.0, {8, 8, 8});
  Seeds s;
  s.points = {{7, 7, 7}};
  constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;
  EXPECT_TRUE(IsError(makePointSeeds(g, {}, &s), kInvalid, "point list is empty"));
  EXPECT_TRUE(IsError(makePointSeeds(g, {{1, std::nan(""), 1}}, &s), kInvalid, "point 0 has a non-finite"));
  EXPECT_TRUE(IsError(makePointSeeds(g, {{1, 1, 1}, {std::numeric_limits<double>::infinity(), 0, 0}}, &s), kInvalid,
                      "point 1 has a non-finite"));
  ASSERT_EQ(s.points.size(), 1u) << "output must be untouched on error";
  EXPECT_EQ(s.points[0].x, 7);
}

std::vector<uint8_t> cubeMask(const Coord& d, int lo, int hi) {
  std::vector<uint8_t> m(size_t(d.x) * d.y * d.z, 0);
  for (int z = lo; z <= hi; ++z)
    for (int y = lo; y <= hi; ++y)
      for (int x = lo; x <= hi; ++x) m[(size_t(z) * d.y + y) * d.x + x] = 1;
  return m;
}

TEST(VolumeSeedsTest, UnsignedBandIsTheMaskWithSitesOnItsBoundary) {
  const Coord d{10, 10, 10};
  const Grid g({0, 0, 0}, 1.0, d);
  const std::vector<uint8_t> mask = cubeMask(d, 3, 6);  // 4^3 = 64 voxels, 2^3 = 8 interior
  Seeds s;
  ASSERT_TRUE(IsOk(makeVolumeSeeds(g, LabelVolume::ofMask(d, mask), false, &s)));
  EXPECT_EQ(s.kind, SiteKind::kPoint);
  EXPECT_EQ(s.band.size(), 64u);
  EXPECT_EQ(s.points.size(), 56u);
  int no_site = 0;
  for (const BandVoxel& b : s.band) {
    EXPECT_TRUE(mask[g.denseIndex(b.voxel)]);
    const bool interior = b.voxel.x >= 4 && b.voxel.x <= 5 && b.voxel.y >= 4 && b.voxel.y <= 5 && b.voxel.z >= 4 &&
                          b.voxel.z <= 5;
    if (b.site == kNoSite) {
      ++no_site;
      EXPECT_TRUE(interior);
    } else {
      ASSERT_LT(b.site, s.points.size());
      // A boundary voxel is its own site.
      EXPECT_EQ(s.points[b.site].x, b.voxel.x);
      EXPECT_EQ(s.points[b.site].y, b.voxel.y);
      EXPECT_EQ(s.points[b.site].z, b.voxel.z);
    }
  }
  EXPECT_EQ(no_site, 8);
  EXPECT_EQ(s.region, nullptr);
  EXPECT_FALSE(s.sign);
}

TEST(VolumeSeedsTest, SignedBandStraddlesTheBoundary) {
  const Coord d{10, 10, 10};
  const Grid g({0, 0, 0}, 1.0, d);
  const std::vector<uint8_t> mask = cubeMask(d, 3, 6);
  Seeds s;
  ASSERT_TRUE(IsOk(makeVolumeSeeds(g, LabelVolume::ofMask(d, mask), true, &s)));
  ASSERT_NE(s.region, nullptr);
  ASSERT_EQ(s.region->size(), mask.size());
  for (size_t i = 0; i < mask.size(); ++i) EXPECT_EQ((*s.region)[i] != 0, mask[i] != 0);
  // Inside boundary: 56 voxels; outside boundary: the 6-neighbours of the cube = 6 faces of 4x4 = 96.
  EXPECT_EQ(s.band.size(), 56u + 96u);
  for (const BandVoxel& b : s.band) {
    ASSERT_LT(b.site, s.points.size());
    const Vec3d p = s.points[b.site];
    const Coord c{int(p.x), int(p.y), int(p.z)};
    // Each band voxel starts from a voxel across the boundary at distance 1.
    EXPECT_NE(mask[g.denseIndex(c)], mask[g.denseIndex(b.voxel)]);
    const double d2 = (p - Vec3d{double(b.voxel.x), double(b.voxel.y), double(b.voxel.z)}).lengthSqr();
    EXPECT_DOUBLE_EQ(d2, 1.0);
  }
  // The sign callback negates masked values of inside voxels only.
  ASSERT_TRUE(s.sign);
  Brick brick;
  brick.origin = {0, 0, 0};
  for (int i = 0; i < kBrickVoxels; ++i) {
    brick.values[i] = 1.5f;
    if (i % 3) brick.mask.set(i);
  }
  std::vector<uint32_t> sites(kBrickVoxels, kNoSite);
  s.sign(brick, sites.data());
  for (int i = 0; i < kBrickVoxels; ++i) {
    const Coord c = brickLocal(i);
    const bool in = mask[g.denseIndex(c)] != 0;
    if (i % 3 && in)
      EXPECT_EQ(brick.values[i], -1.5f);
    else
      EXPECT_EQ(brick.values[i], 1.5f);
  }
}

TEST(VolumeSeedsTest, Errors) {
  const Coord d{6, 6, 6};
  const Grid g({0, 0, 0}, 1.0, d);
  Seeds s;
  s.points = {{1, 2, 3}};
  constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;
  EXPECT_TRUE(IsError(makeVolumeSeeds(g, LabelVolume::ofMask({10, 1, 1}, std::vector<uint8_t>(10, 1)), false, &s), kInvalid,
                      "the volume has 10 voxels, the grid 216"));
  EXPECT_TRUE(IsError(makeVolumeSeeds(g, LabelVolume::ofMask(d, std::vector<uint8_t>(216, 0)), false, &s), kInvalid, "no nonzero voxel"));
  EXPECT_TRUE(IsError(makeVolumeSeeds(g, LabelVolume::ofMask(d, std::vector<uint8_t>(216, 0)), true, &s), kInvalid, "no nonzero voxel"));
  EXPECT_TRUE(IsError(makeVolumeSeeds(g, LabelVolume::ofMask(d, std::vector<uint8_t>(216, 7)), true, &s), kInvalid, "no zero voxel"));
  EXPECT_TRUE(IsOk(makeVolumeSeeds(g, LabelVolume::ofMask(d, std::vector<uint8_t>(216, 7)), false, &s)));  // full mask: all zero
  s.points = {{1, 2, 3}};
  EXPECT_TRUE(IsError(makeVolumeSeeds(g, LabelVolume::ofMask({217, 1, 1}, std::vector<uint8_t>(217, 1)), true, &s), kInvalid,
                      "the volume has 217 voxels"));
  ASSERT_EQ(s.points.size(), 1u) << "output must be untouched on error";
}

// checkVolumeMeasure scans in word steps and parallel slices: a lone seed (or a lone zero) anywhere, at any size and
// element width, counts.
TEST(VolumeSeedsTest, CheckVolumeMeasureFindsALoneVoxelAnywhere) {
  const VolumeMeasure unsigned_field{}, signed_field{false, true, false};
  for (VoxelType type : kVoxelTypes)
    for (size_t size : {size_t(1), size_t(7), size_t(8), size_t(9), size_t(1) << 20, (size_t(3) << 20) + 5}) {
      const size_t w = voxelTypeBytes(type);
      auto volume = [&](uint8_t fill, size_t at, uint8_t value) {
        std::vector<uint8_t> bytes(size * w, fill);
        if (at < size) std::fill_n(bytes.begin() + int64_t(at * w), w, value);
        if (at < size && value) bytes[at * w + w - 1] = value;  // a nonzero element whose low bytes may be zero
        return LabelVolume({int(size), 1, 1}, type, std::make_shared<const std::vector<uint8_t>>(std::move(bytes)));
      };
      for (size_t at : {size_t(0), size / 2, size - 1}) {
        EXPECT_TRUE(IsError(checkVolumeMeasure(volume(0, size, 0), unsigned_field), Status::Code::kInvalidArgument,
                            "no nonzero voxel"))
            << size;
        EXPECT_TRUE(IsOk(checkVolumeMeasure(volume(0, at, 200), unsigned_field))) << size << " " << at;
        EXPECT_TRUE(IsError(checkVolumeMeasure(volume(1, size, 0), signed_field), Status::Code::kInvalidArgument,
                            "no zero voxel"))
            << size;
        if (size > 1)
          EXPECT_TRUE(IsOk(checkVolumeMeasure(volume(1, at, 0), signed_field))) << size << " " << at;
        else
          EXPECT_TRUE(IsError(checkVolumeMeasure(volume(1, at, 0), unsigned_field), Status::Code::kInvalidArgument,
                              "no nonzero voxel"));
      }
    }
  // The multi-label EDT: two labels, or a black border.
  const LabelVolume one({4, 1, 1}, VoxelType::kUint16, std::make_shared<const std::vector<uint8_t>>(8, 3));
  EXPECT_TRUE(
      IsError(checkVolumeMeasure(one, {true, false, 0}), Status::Code::kInvalidArgument, "every voxel has label 771"));
  // All background: every distance is 0.
  EXPECT_TRUE(IsOk(
      checkVolumeMeasure(LabelVolume({4, 1, 1}, VoxelType::kUint16, std::make_shared<const std::vector<uint8_t>>(8, 0)),
                         {true, false, 0})));
  EXPECT_TRUE(IsOk(checkVolumeMeasure(one, {true, false, kAllFaces})));
  EXPECT_TRUE(IsOk(checkVolumeMeasure(one, {true, false, 0x4})));  // a tile's one face on the grid's
  std::vector<uint8_t> two(8, 3);
  two[6] = 4;
  EXPECT_TRUE(IsOk(
      checkVolumeMeasure(LabelVolume({4, 1, 1}, VoxelType::kUint16, std::make_shared<const std::vector<uint8_t>>(two)),
                         {true, false, 0})));
}

TEST(VolumeSeedsTest, NonzeroValuesOtherThanOneCount) {
  const Coord d{6, 6, 6};
  const Grid g({0, 0, 0}, 1.0, d);
  std::vector<uint8_t> mask(216, 0);
  mask[g.denseIndex({2, 2, 2})] = 255;
  Seeds s;
  ASSERT_TRUE(IsOk(makeVolumeSeeds(g, LabelVolume::ofMask(d, mask), false, &s)));
  ASSERT_EQ(s.band.size(), 1u);
  EXPECT_EQ(s.band[0].voxel, (Coord{2, 2, 2}));
}

}  // namespace
}  // namespace distband
