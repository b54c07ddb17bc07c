// Tests for core/io/slice_png: geometry, colours and contour of a slice of an analytic sphere, read back with
// libpng; parsing and range errors.
#include "core/io/slice_png.h"

#include <png.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

namespace fs = std::filesystem;

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
  Rgb8 at(int x, int y) const {
    const size_t i = (size_t(y) * width + x) * 3;
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

Image readPng(const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  Image out;
  if (!png_image_begin_read_from_file(&image, path.c_str())) {
    ADD_FAILURE() << "cannot read " << path << ": " << image.message;
    return out;
  }
  image.format = PNG_FORMAT_RGB;
  out.width = int(image.width);
  out.height = int(image.height);
  out.rgb.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, out.rgb.data(), 0, nullptr)) {
    ADD_FAILURE() << "cannot decode " << path << ": " << image.message;
    out = {};
  }
  return out;
}

class SlicePngTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("distband_slice_png_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// A 64^3 grid, voxel size 0.5, origin (-8, -8, -8); a sphere of radius 10.2 centred at voxel (32, 32, 20), i.e.
// off-centre in z so that a wrong vertical orientation is caught.
const Grid kGrid({-8, -8, -8}, 0.5, {64, 64, 64});
const Vec3d kCentre = kGrid.worldOf({32, 32, 20});
constexpr double kRadius = 10.2;

double sphereDistance(const Coord& c) { return (kGrid.worldOf(c) - kCentre).length() - kRadius; }
float sphereSample(const Coord& c) { return float(sphereDistance(c)); }

TEST_F(SlicePngTest, SphereSliceHasSizeColoursAndContourWhereExpected) {
  const std::string file = path("y32.png");
  SlicePngOptions options;
  options.limit_world = 5;
  SlicePngInfo info;
  ASSERT_EQ(writeSlicePng(file, kGrid, sphereSample, {1, 32}, options, &info), "");
  // Automatic scale: 512 / 64 = 8 pixels per voxel.
  EXPECT_EQ(info.scale, 8);
  EXPECT_EQ(info.width, 512);
  EXPECT_EQ(info.height, 512);
  EXPECT_DOUBLE_EQ(info.limit_world, 5);

  const Image img = readPng(file);
  ASSERT_EQ(img.width, 512);
  ASSERT_EQ(img.height, 512);
  // Axis y: columns are x, rows are z with the largest z at the top.
  auto pixelOf = [&](int x, int z) { return img.at(x * 8 + 4, (63 - z) * 8 + 4); };
  // Centre of the sphere: 10.2 inside, saturated inside colour.
  EXPECT_EQ(pixelOf(32, 20), kSliceInsideColour);
  // Top middle (z = 63): 21.5 - 10.2 = 11.3 outside, saturated red.
  EXPECT_EQ(pixelOf(32, 63), kSliceOutsideColour);
  // z = 2: 9 - 10.2 = -1.2 → inside; seen at image row (63 - 2). A vertically flipped writer would show
  // z = 61 (outside, red) there.
  EXPECT_EQ(pixelOf(32, 2), sliceColour(float(sphereDistance({32, 32, 2})), 5));
  EXPECT_LT(sphereDistance({32, 32, 2}), 0);
  // A mid-range outside value blends halfway: corner (0, 0) → distance from the analytic field.
  EXPECT_EQ(pixelOf(0, 0), sliceColour(float(sphereDistance({0, 32, 0})), 5));
  // The colour map itself: white at 0, halfway at limit / 2, saturated beyond the limit.
  EXPECT_EQ(sliceColour(0.f, 5), kSliceZeroColour);
  EXPECT_EQ(sliceColour(2.5f, 5), (Rgb8{217, 140, 149}));
  EXPECT_EQ(sliceColour(-2.5f, 5), (Rgb8{144, 179, 214}));
  EXPECT_EQ(sliceColour(50.f, 5), kSliceOutsideColour);
  EXPECT_EQ(sliceColour(-50.f, 5), kSliceInsideColour);
  EXPECT_EQ(sliceColour(std::numeric_limits<float>::quiet_NaN(), 5), kSliceInvalidColour);

  // Along the row z = 20 through the centre: x = 32 ± 20 is at distance 10 - 10.2 = -0.2 (inside, nearer zero
  // than its outside neighbour at +0.3), so x = 12 and x = 52 are black and their neighbours are not.
  EXPECT_EQ(pixelOf(12, 20), kSliceContourColour);
  EXPECT_EQ(pixelOf(52, 20), kSliceContourColour);
  EXPECT_NE(pixelOf(11, 20), kSliceContourColour);
  EXPECT_NE(pixelOf(13, 20), kSliceContourColour);
  EXPECT_NE(pixelOf(51, 20), kSliceContourColour);
  EXPECT_NE(pixelOf(53, 20), kSliceContourColour);

  // Over the whole slice: black voxels lie within h/2 of the surface, every sign change has a black voxel.
  int64_t black = 0;
  for (int z = 0; z < 64; ++z)
    for (int x = 0; x < 64; ++x) {
      const double d = sphereDistance({x, 32, z});
      const bool is_black = pixelOf(x, z) == kSliceContourColour;
      if (is_black) {
        ++black;
        EXPECT_LE(std::abs(d), 0.5 * kGrid.voxelSize() + 1e-6) << "x=" << x << " z=" << z;
      }
      for (const Coord n : {Coord{x + 1, 32, z}, Coord{x, 32, z + 1}}) {
        if (n.x >= 64 || n.z >= 64) continue;
        const double dn = sphereDistance(n);
        if ((d < 0) != (dn < 0)) {
          EXPECT_TRUE(is_black || pixelOf(n.x, n.z) == kSliceContourColour) << "gap at x=" << x << " z=" << z;
        }
      }
      // Every pixel of a voxel's 8x8 block has the same colour.
      const Rgb8 c = pixelOf(x, z);
      EXPECT_EQ(img.at(x * 8, (63 - z) * 8), c);
      EXPECT_EQ(img.at(x * 8 + 7, (63 - z) * 8 + 7), c);
    }
  EXPECT_EQ(black, info.contour_voxels);
  // The circle has circumference 2*pi*20.4 voxels ~ 128; a 4-connected contour holds more voxels than that.
  EXPECT_GT(black, 100);
  EXPECT_LT(black, 300);
  // No temporary file is left behind.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
}

TEST_F(SlicePngTest, DenseFieldGivesTheSameImageAsTheSampler) {
  DenseField field(kGrid, 5.f);
  for (int z = 0; z < 64; ++z)
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) field.values()[kGrid.denseIndex({x, y, z})] = sphereSample({x, y, z});
  SlicePngOptions options;
  options.scale = 2;
  options.limit_world = 4;
  ASSERT_EQ(writeSlicePng(path("a.png"), kGrid, sphereSample, {0, 40}, options), "");
  ASSERT_EQ(writeSlicePng(path("b.png"), field, {0, 40}, options), "");
  const Image a = readPng(path("a.png")), b = readPng(path("b.png"));
  EXPECT_EQ(a.width, 128);
  EXPECT_EQ(a.height, 128);
  EXPECT_EQ(a.rgb, b.rgb);
  // Axis x: columns are y, rows z. Voxel (40, 32, 20) is 4 voxels = 2 world units off-centre: inside.
  EXPECT_EQ(a.at(32 * 2, (63 - 20) * 2), sliceColour(float(sphereDistance({40, 32, 20})), 4));
}

TEST_F(SlicePngTest, AutomaticLimitAndScaleForSmallGrids) {
  const Grid grid({0, 0, 0}, 1.0, {10, 6, 3});
  SlicePngInfo info;
  ASSERT_EQ(writeSlicePng(
                path("small.png"), grid, [](const Coord& c) { return float(c.x) - 4.5f; }, {2, 1}, {}, &info),
            "");
  EXPECT_EQ(info.scale, 16);  // 512 / 10 → 52, capped at 16
  EXPECT_EQ(info.width, 160);
  EXPECT_EQ(info.height, 96);
  EXPECT_DOUBLE_EQ(info.limit_world, 4.5);  // max |x - 4.5| over the slice
  EXPECT_EQ(info.contour_voxels, 6);        // x = 4 (value -0.5) in every row; ties go inside
  const Image img = readPng(path("small.png"));
  EXPECT_EQ(img.at(4 * 16 + 8, 8), kSliceContourColour);
  EXPECT_EQ(img.at(5 * 16 + 8, 8), sliceColour(0.5f, 4.5));
  EXPECT_EQ(img.at(9 * 16 + 8, 8), kSliceOutsideColour);
}

TEST_F(SlicePngTest, BackgroundSeamsAreNotDrawnAsContours) {
  // A clamped field whose inside beyond the limit holds +limit (as a dense field's background does): the jump
  // from -3 to +3 is not a surface.
  const Grid grid({0, 0, 0}, 1.0, {20, 4, 1});
  auto seam = [](const Coord& c) { return c.x < 10 ? -3.f : 3.f; };
  SlicePngInfo info;
  ASSERT_EQ(writeSlicePng(path("seam.png"), grid, seam, {2, 0}, {}, &info), "");
  EXPECT_EQ(info.contour_voxels, 0);
  SlicePngOptions every;
  every.contour_max_jump_world = std::numeric_limits<double>::infinity();
  ASSERT_EQ(writeSlicePng(path("seam2.png"), grid, seam, {2, 0}, every, &info), "");
  EXPECT_EQ(info.contour_voxels, 4);  // tie → the inside voxel x = 9 of each of the 4 rows
  SlicePngOptions none;
  none.draw_contour = false;
  ASSERT_EQ(writeSlicePng(path("seam3.png"), grid, [](const Coord& c) { return c.x - 9.5f; }, {2, 0}, none, &info),
            "");
  EXPECT_EQ(info.contour_voxels, 0);
}

TEST(SliceSpecTest, ParsesAxisAndIndex) {
  SliceSpec s;
  ASSERT_EQ(parseSliceSpec("x:5", &s), "");
  EXPECT_EQ(s.axis, 0);
  EXPECT_EQ(s.index, 5);
  ASSERT_EQ(parseSliceSpec("Z:0", &s), "");
  EXPECT_EQ(s.axis, 2);
  EXPECT_EQ(s.index, 0);
  ASSERT_EQ(parseSliceSpec("y:mid", &s), "");
  EXPECT_EQ(s.axis, 1);
  EXPECT_EQ(s.index, -1);
  SliceSpec r = s;
  ASSERT_EQ(resolveSlice(Grid({0, 0, 0}, 1, {4, 9, 2}), &r), "");
  EXPECT_EQ(r.index, 4);
}

TEST(SliceSpecTest, RejectsMalformedSpecs) {
  SliceSpec s{1, 7};
  for (const char* bad : {"", "z", "w:3", "xy:3", ":3", "z:", "z:-1", "z:abc", "z:1x", "z:1.5"}) {
    const std::string err = parseSliceSpec(bad, &s);
    EXPECT_FALSE(err.empty()) << "'" << bad << "'";
  }
  EXPECT_NE(parseSliceSpec("w:3", &s).find("axis must be x, y or z"), std::string::npos);
  EXPECT_NE(parseSliceSpec("z:-1", &s).find("non-negative integer"), std::string::npos);
  EXPECT_EQ(s.axis, 1);  // untouched on error
  EXPECT_EQ(s.index, 7);
}

TEST_F(SlicePngTest, OutOfRangeIndexIsAnErrorAndWritesNothing) {
  const std::string file = path("bad.png");
  std::string err = writeSlicePng(file, kGrid, sphereSample, {2, 64});
  EXPECT_NE(err.find("outside the grid"), std::string::npos) << err;
  EXPECT_NE(err.find("0..63"), std::string::npos) << err;
  err = writeSlicePng(file, kGrid, sphereSample, {3, 0});
  EXPECT_NE(err.find("axis"), std::string::npos) << err;
  err = writeSlicePng(file, kGrid, sphereSample, {0, -5});
  EXPECT_FALSE(err.empty());
  SlicePngOptions huge;
  huge.scale = 1000;
  err = writeSlicePng(file, kGrid, sphereSample, {0, 1}, huge);
  EXPECT_NE(err.find("pixel edge limit"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(file));
  // An unwritable destination reports the OS error and leaves no temporary file.
  err = writeSlicePng((dir_ / "missing" / "x.png").string(), kGrid, sphereSample, {0, 1});
  EXPECT_NE(err.find("temporary file"), std::string::npos) << err;
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 0);
}

}  // namespace
}  // namespace distband
