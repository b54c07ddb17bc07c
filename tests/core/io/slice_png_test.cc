// Tests for core/io/slice_png: geometry, colours and contour of a slice of an analytic sphere, read back with
// libpng; the title strip and colour bar around it; the bitmap font; parsing and range errors.
#include "core/io/slice_png.h"

#include "core/io/bitmap_font.h"

#include <png.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/status_testing.h"

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
  ASSERT_TRUE(IsOk(writeSlicePng(file, kGrid, sphereSample, {1, 32}, options, &info)));
  // Automatic scale: 512 / 64 = 8 pixels per voxel.
  EXPECT_EQ(info.scale, 8);
  EXPECT_EQ(info.slice.width, 512);
  EXPECT_EQ(info.slice.height, 512);
  EXPECT_DOUBLE_EQ(info.limit_world, 5);

  const Image img = readPng(file);
  ASSERT_EQ(img.width, info.width);
  ASSERT_EQ(img.height, info.height);
  // Axis y: columns are x, rows are z with the largest z at the top; the slice starts at info.slice's corner.
  auto sliceAt = [&](int x, int y) { return img.at(info.slice.left + x, info.slice.top + y); };
  auto pixelOf = [&](int x, int z) { return sliceAt(x * 8 + 4, (63 - z) * 8 + 4); };
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
      EXPECT_EQ(sliceAt(x * 8, (63 - z) * 8), c);
      EXPECT_EQ(sliceAt(x * 8 + 7, (63 - z) * 8 + 7), c);
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
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("a.png"), kGrid, sphereSample, {0, 40}, options, &info)));
  ASSERT_TRUE(IsOk(writeSlicePng(path("b.png"), field, {0, 40}, options)));
  const Image a = readPng(path("a.png")), b = readPng(path("b.png"));
  EXPECT_EQ(info.slice.width, 128);
  EXPECT_EQ(info.slice.height, 128);
  EXPECT_EQ(a.rgb, b.rgb);
  // Axis x: columns are y, rows z. Voxel (40, 32, 20) is 4 voxels = 2 world units off-centre: inside.
  EXPECT_EQ(a.at(info.slice.left + 32 * 2, info.slice.top + (63 - 20) * 2),
            sliceColour(float(sphereDistance({40, 32, 20})), 4));
}

TEST_F(SlicePngTest, AutomaticLimitAndScaleForSmallGrids) {
  const Grid grid({0, 0, 0}, 1.0, {10, 6, 3});
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(
      path("small.png"), grid, [](const Coord& c) { return float(c.x) - 4.5f; }, {2, 1}, {}, &info)));
  EXPECT_EQ(info.scale, 16);  // 512 / 10 → 52, capped at 16
  EXPECT_EQ(info.slice.width, 160);
  EXPECT_EQ(info.slice.height, 96);
  EXPECT_EQ(info.text_scale, 1);  // below 256 pixels
  EXPECT_DOUBLE_EQ(info.limit_world, 4.5);  // max |x - 4.5| over the slice
  EXPECT_EQ(info.contour_voxels, 6);        // x = 4 (value -0.5) in every row; ties go inside
  const Image img = readPng(path("small.png"));
  const int left = info.slice.left, top = info.slice.top;
  EXPECT_EQ(img.at(left + 4 * 16 + 8, top + 8), kSliceContourColour);
  EXPECT_EQ(img.at(left + 5 * 16 + 8, top + 8), sliceColour(0.5f, 4.5));
  EXPECT_EQ(img.at(left + 9 * 16 + 8, top + 8), kSliceOutsideColour);
}

TEST_F(SlicePngTest, BackgroundSeamsAreNotDrawnAsContours) {
  // A clamped field whose inside beyond the limit holds +limit (as a dense field's background does): the jump
  // from -3 to +3 is not a surface.
  const Grid grid({0, 0, 0}, 1.0, {20, 4, 1});
  auto seam = [](const Coord& c) { return c.x < 10 ? -3.f : 3.f; };
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("seam.png"), grid, seam, {2, 0}, {}, &info)));
  EXPECT_EQ(info.contour_voxels, 0);
  SlicePngOptions every;
  every.contour_max_jump_world = std::numeric_limits<double>::infinity();
  ASSERT_TRUE(IsOk(writeSlicePng(path("seam2.png"), grid, seam, {2, 0}, every, &info)));
  EXPECT_EQ(info.contour_voxels, 4);  // tie → the inside voxel x = 9 of each of the 4 rows
  SlicePngOptions none;
  none.draw_contour = false;
  ASSERT_TRUE(
      IsOk(writeSlicePng(path("seam3.png"), grid, [](const Coord& c) { return c.x - 9.5f; }, {2, 0}, none, &info)));
  EXPECT_EQ(info.contour_voxels, 0);
}

/// The pixels of `rect` in `img`, row by row (for comparing a region with a whole image).
std::vector<uint8_t> crop(const Image& img, const PixelRect& rect) {
  std::vector<uint8_t> out;
  for (int y = rect.top; y < rect.top + rect.height; ++y)
    for (int x = rect.left; x < rect.left + rect.width; ++x) {
      const Rgb8 c = img.at(x, y);
      out.insert(out.end(), c.begin(), c.end());
    }
  return out;
}

/// The colour bar's middle row, left to right.
std::vector<Rgb8> barRow(const Image& img, const PixelRect& bar) {
  std::vector<Rgb8> out;
  for (int x = bar.left; x < bar.left + bar.width; ++x) out.push_back(img.at(x, bar.top + bar.height / 2));
  return out;
}

bool contains(const PixelRect& outer, const PixelRect& inner) {
  return inner.left >= outer.left && inner.top >= outer.top && inner.left + inner.width <= outer.left + outer.width &&
         inner.top + inner.height <= outer.top + outer.height;
}

TEST_F(SlicePngTest, TitleAndColourBarSurroundTheUnchangedSlice) {
  SlicePngOptions bare;
  bare.limit_world = 5;
  bare.draw_title = false;
  bare.draw_colour_bar = false;
  SlicePngInfo bare_info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("bare.png"), kGrid, sphereSample, {1, 32}, bare, &bare_info)));
  // Without decorations the picture is the slice alone, as before the title and bar existed.
  EXPECT_EQ(bare_info.width, 512);
  EXPECT_EQ(bare_info.height, 512);
  EXPECT_EQ(bare_info.slice.left, 0);
  EXPECT_EQ(bare_info.slice.top, 0);

  SlicePngOptions decorated;
  decorated.limit_world = 5;
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("decorated.png"), kGrid, sphereSample, {1, 32}, decorated, &info)));
  const Image img = readPng(path("decorated.png")), bare_img = readPng(path("bare.png"));
  ASSERT_EQ(img.width, info.width);
  ASSERT_EQ(img.height, info.height);
  EXPECT_EQ(info.text_scale, 2);  // 512-pixel slice
  // Same slice pixels, same scale and orientation, moved by the margin and the title strip.
  EXPECT_EQ(info.slice.width, bare_info.slice.width);
  EXPECT_EQ(info.slice.height, bare_info.slice.height);
  EXPECT_EQ(crop(img, info.slice), bare_img.rgb);
  // Title above the slice, bar below it, all inside the image.
  const PixelRect whole{0, 0, img.width, img.height};
  EXPECT_TRUE(contains(whole, info.slice));
  EXPECT_TRUE(contains(whole, info.title));
  EXPECT_TRUE(contains(whole, info.bar));
  EXPECT_LT(info.title.top + info.title.height, info.slice.top);
  EXPECT_GT(info.bar.top, info.slice.top + info.slice.height);
  // The frame around the slice is neither margin nor slice.
  EXPECT_EQ(img.at(info.slice.left - 1, info.slice.top + 100), kSliceFrameColour);
  EXPECT_EQ(img.at(info.slice.left + info.slice.width, info.slice.top + 100), kSliceFrameColour);
}

TEST_F(SlicePngTest, TitleStripCarriesTheSlicePositionAsText) {
  SlicePngOptions options;
  options.limit_world = 5;
  SlicePngInfo at3, at40, prefixed;
  ASSERT_TRUE(IsOk(writeSlicePng(path("z3.png"), kGrid, sphereSample, {2, 3}, options, &at3)));
  ASSERT_TRUE(IsOk(writeSlicePng(path("z40.png"), kGrid, sphereSample, {2, 40}, options, &at40)));
  const Image z3 = readPng(path("z3.png")), z40 = readPng(path("z40.png"));
  // Text pixels in the title line, and only margin in the strip's first row above it.
  int text_pixels = 0;
  for (int y = at3.title.top; y < at3.title.top + at3.title.height; ++y)
    for (int x = 0; x < z3.width; ++x) text_pixels += z3.at(x, y) == kSliceTextColour;
  EXPECT_GT(text_pixels, 100);
  for (int x = 0; x < z3.width; ++x) ASSERT_EQ(z3.at(x, 0), kSliceMarginColour) << x;
  // "z = 3 (world -6.5)" against "z = 40 (world 12)": the title reflects the slice position.
  EXPECT_NE(crop(z3, at3.title), crop(z40, at40.title));
  EXPECT_EQ(at3.title.width, textWidth("z = 3 (world -6.5)  |  distance, world units", at3.text_scale));
  EXPECT_EQ(at40.title.width, textWidth("z = 40 (world 12)  |  distance, world units", at40.text_scale));
  // A prefix and other units lengthen the line by exactly their text.
  options.title_prefix = "bunny.obj";
  options.units = "mm";
  ASSERT_TRUE(IsOk(writeSlicePng(path("prefixed.png"), kGrid, sphereSample, {2, 3}, options, &prefixed)));
  EXPECT_EQ(prefixed.title.width,
            textWidth("bunny.obj  |  z = 3 (world -6.5)  |  distance, mm", prefixed.text_scale));
}

TEST_F(SlicePngTest, SignedBarRunsFromInsideThroughWhiteToOutside) {
  SlicePngOptions options;
  options.limit_world = 0.25;
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("bar.png"), kGrid, sphereSample, {2, 20}, options, &info)));
  EXPECT_TRUE(info.signed_bar);  // the sphere's inside is negative
  const Image img = readPng(path("bar.png"));
  const std::vector<Rgb8> row = barRow(img, info.bar);
  ASSERT_GE(row.size(), 3u);
  ASSERT_EQ(row.size() % 2, 1u);
  const size_t middle = row.size() / 2;
  EXPECT_EQ(row.front(), kSliceInsideColour);
  EXPECT_EQ(row[middle], kSliceZeroColour);
  EXPECT_EQ(row.back(), kSliceOutsideColour);
  // Every channel rises from the inside colour to white, then falls to the outside colour; each column is the
  // slice's own colour map at its value.
  for (size_t i = 0; i + 1 < row.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) {
      if (i < middle) EXPECT_LE(row[i][ch], row[i + 1][ch]) << i;
      else EXPECT_GE(row[i][ch], row[i + 1][ch]) << i;
    }
  for (size_t i = 0; i < row.size(); ++i)
    EXPECT_EQ(row[i], sliceColour(float(-0.25 + 0.5 * double(i) / double(row.size() - 1)), 0.25)) << i;
  // The whole height of the bar is the gradient.
  for (int y = info.bar.top; y < info.bar.top + info.bar.height; ++y)
    EXPECT_EQ(img.at(info.bar.left + 1, y), row[1]);
  // Tick marks under the ends and the middle; labels below them.
  const int ticks_top = info.bar.top + info.bar.height + 2;
  EXPECT_EQ(img.at(info.bar.left, ticks_top), kSliceTextColour);
  EXPECT_EQ(img.at(info.bar.left + int(middle), ticks_top), kSliceTextColour);
  EXPECT_EQ(img.at(info.bar.left + info.bar.width - 1, ticks_top), kSliceTextColour);
  EXPECT_EQ(img.at(info.bar.left + int(middle) / 2, ticks_top), kSliceMarginColour);
  // The legend's zero-contour swatch: contour-coloured pixels below the bar.
  int swatch = 0;
  for (int y = ticks_top; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) swatch += img.at(x, y) == kSliceContourColour;
  EXPECT_GT(swatch, 50);
}

TEST_F(SlicePngTest, UnsignedBarStartsAtWhite) {
  // |x - 4.5|: no negative value, so the automatic choice is an unsigned bar over 0..limit.
  const Grid grid({0, 0, 0}, 1.0, {10, 6, 3});
  auto unsigned_field = [](const Coord& c) { return std::abs(float(c.x) - 4.5f); };
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("unsigned.png"), grid, unsigned_field, {2, 1}, {}, &info)));
  EXPECT_FALSE(info.signed_bar);
  const Image img = readPng(path("unsigned.png"));
  const std::vector<Rgb8> row = barRow(img, info.bar);
  ASSERT_GE(row.size(), 2u);
  EXPECT_EQ(row.front(), kSliceZeroColour);
  EXPECT_EQ(row.back(), kSliceOutsideColour);
  for (size_t i = 0; i + 1 < row.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) EXPECT_GE(row[i][ch], row[i + 1][ch]) << i;

  // The sign can be forced either way: a signed field drawn unsigned loses its inside half of the bar, an
  // all-positive slice of a signed field keeps it.
  SlicePngOptions forced;
  forced.sign = SliceSign::kUnsigned;
  ASSERT_TRUE(IsOk(writeSlicePng(path("forced_unsigned.png"), kGrid, sphereSample, {2, 20}, forced, &info)));
  EXPECT_FALSE(info.signed_bar);
  EXPECT_EQ(barRow(readPng(path("forced_unsigned.png")), info.bar).front(), kSliceZeroColour);
  forced.sign = SliceSign::kSigned;
  ASSERT_TRUE(IsOk(writeSlicePng(path("forced_signed.png"), grid, unsigned_field, {2, 1}, forced, &info)));
  EXPECT_TRUE(info.signed_bar);
  EXPECT_EQ(barRow(readPng(path("forced_signed.png")), info.bar).front(), kSliceInsideColour);
}

TEST_F(SlicePngTest, DecoratedImageStaysWithinTheEdgeLimit) {
  // A slice exactly as wide as the limit fits bare, but not with a margin around it.
  const Grid wide({0, 0, 0}, 1.0, {kSliceMaxImageEdge, 2, 1});
  auto ramp = [](const Coord& c) { return float(c.x) - 100.f; };
  SlicePngOptions options;
  options.scale = 1;
  EXPECT_TRUE(IsError(writeSlicePng(path("wide.png"), wide, ramp, {2, 0}, options),
                      Status::Code::kResourceExhausted, "pixel edge limit"));
  EXPECT_FALSE(fs::exists(path("wide.png")));
  options.draw_title = false;
  options.draw_colour_bar = false;
  SlicePngInfo info;
  ASSERT_TRUE(IsOk(writeSlicePng(path("wide.png"), wide, ramp, {2, 0}, options, &info)));
  EXPECT_EQ(info.width, kSliceMaxImageEdge);
  // A very long title widens the picture only up to the limit and is cut off there.
  SlicePngOptions long_title;
  long_title.title_prefix = std::string(4000, 'w');
  ASSERT_TRUE(IsOk(writeSlicePng(path("long.png"), kGrid, sphereSample, {2, 3}, long_title, &info)));
  EXPECT_EQ(info.width, kSliceMaxImageEdge);
  EXPECT_GT(info.title.width, kSliceMaxImageEdge);
  EXPECT_EQ(readPng(path("long.png")).width, kSliceMaxImageEdge);
}

/// The font pixels of one character drawn at scale 1, row-major, '#' for set and '.' for clear.
std::string glyphBitmap(char ch) {
  RgbImage canvas(kGlyphWidth, kGlyphHeight, {255, 255, 255});
  drawText(&canvas, 0, 0, std::string_view(&ch, 1), 1, {0, 0, 0});
  std::string bits;
  for (int y = 0; y < kGlyphHeight; ++y)
    for (int x = 0; x < kGlyphWidth; ++x) bits += canvas.pixel(x, y)[0] == 0 ? '#' : '.';
  return bits;
}

TEST(BitmapFontTest, EveryGlyphRendersAndDiffers) {
  const std::string chars = bitmapFontCharacters();
  for (const char ch : std::string("0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ .-+=(),:|/_"))
    EXPECT_NE(chars.find(ch), std::string::npos) << "no glyph for '" << ch << "'";
  const std::string missing = glyphBitmap('#');  // not in the table: a box
  EXPECT_EQ(chars.find('#'), std::string::npos);
  EXPECT_EQ(std::count(missing.begin(), missing.end(), '#'), 2 * kGlyphWidth + 2 * (kGlyphHeight - 2));
  std::set<std::string> seen;
  for (const char ch : chars) {
    const std::string bits = glyphBitmap(ch);
    if (ch == ' ') {
      EXPECT_EQ(bits.find('#'), std::string::npos);
      continue;
    }
    EXPECT_NE(bits.find('#'), std::string::npos) << "'" << ch << "' draws nothing";
    EXPECT_NE(bits, missing) << "'" << ch << "' looks like a missing glyph";
    EXPECT_TRUE(seen.insert(bits).second) << "'" << ch << "' has the bitmap of an earlier glyph";
  }
}

TEST(BitmapFontTest, ScaleWidthAndClipping) {
  EXPECT_EQ(textWidth("", 2), 0);
  EXPECT_EQ(textWidth("7", 1), kGlyphWidth);
  EXPECT_EQ(textWidth("-0.25", 2), (5 * kGlyphAdvance - 1) * 2);
  // At scale 3 every font pixel is a 3x3 block: nine times the pixels.
  RgbImage small(kGlyphWidth, kGlyphHeight, {255, 255, 255});
  RgbImage large(3 * kGlyphWidth, 3 * kGlyphHeight, {255, 255, 255});
  drawText(&small, 0, 0, "8", 1, {0, 0, 0});
  drawText(&large, 0, 0, "8", 3, {0, 0, 0});
  EXPECT_EQ(std::count(large.rgb.begin(), large.rgb.end(), 0), 9 * std::count(small.rgb.begin(), small.rgb.end(), 0));
  EXPECT_EQ(large.pixel(3 * 1, 0)[0], 0);  // '8' row 0 is .###.: font column 1 → pixels 3..5
  EXPECT_EQ(large.pixel(2, 0)[0], 255);
  // Text partly outside the image is clipped, not written out of bounds.
  RgbImage clipped(8, 8, {255, 255, 255});
  drawText(&clipped, -3, -4, "W88", 2, {0, 0, 0});
  EXPECT_EQ(clipped.rgb.size(), size_t(8 * 8 * 3));
  EXPECT_GT(std::count(clipped.rgb.begin(), clipped.rgb.end(), 0), 0);
}

TEST(SliceSpecTest, ParsesAxisAndIndex) {
  SliceSpec s;
  ASSERT_TRUE(IsOk(parseSliceSpec("x:5", &s)));
  EXPECT_EQ(s.axis, 0);
  EXPECT_EQ(s.index, 5);
  ASSERT_TRUE(IsOk(parseSliceSpec("Z:0", &s)));
  EXPECT_EQ(s.axis, 2);
  EXPECT_EQ(s.index, 0);
  ASSERT_TRUE(IsOk(parseSliceSpec("y:mid", &s)));
  EXPECT_EQ(s.axis, 1);
  EXPECT_EQ(s.index, -1);
  SliceSpec r = s;
  ASSERT_TRUE(IsOk(resolveSlice(Grid({0, 0, 0}, 1, {4, 9, 2}), &r)));
  EXPECT_EQ(r.index, 4);
}

TEST(SliceSpecTest, RejectsMalformedSpecs) {
  SliceSpec s{1, 7};
  const std::pair<const char*, const char*> cases[] = {
      {"", "must be AXIS:INDEX with AXIS x, y or z (got '')"},
      {"z", "must be AXIS:INDEX with AXIS x, y or z (got 'z')"},
      {"w:3", "axis must be x, y or z (got 'w')"},
      {"xy:3", "axis must be x, y or z (got 'xy')"},
      {":3", "axis must be x, y or z (got '')"},
      {"z:", "index must be a non-negative integer or 'mid' (got '')"},
      {"z:-1", "index must be a non-negative integer or 'mid' (got '-1')"},
      {"z:abc", "non-negative integer or 'mid' (got 'abc')"},
      {"z:1x", "non-negative integer or 'mid' (got '1x')"},
      {"z:1.5", "non-negative integer or 'mid' (got '1.5')"},
  };
  for (const auto& [bad, names] : cases)
    EXPECT_TRUE(IsError(parseSliceSpec(bad, &s), Status::Code::kInvalidArgument, names)) << "'" << bad << "'";
  EXPECT_EQ(s.axis, 1);  // untouched on error
  EXPECT_EQ(s.index, 7);
}

TEST_F(SlicePngTest, OutOfRangeIndexIsAnErrorAndWritesNothing) {
  const std::string file = path("bad.png");
  constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;
  EXPECT_TRUE(IsError(writeSlicePng(file, kGrid, sphereSample, {2, 64}), kInvalid,
                      "slice index z:64 is outside the grid (valid: 0..63 along z)"));
  EXPECT_TRUE(
      IsError(writeSlicePng(file, kGrid, sphereSample, {3, 0}), kInvalid, "slice axis must be 0, 1 or 2 (got 3)"));
  EXPECT_TRUE(
      IsError(writeSlicePng(file, kGrid, sphereSample, {0, -5}), kInvalid, "slice index x:-5 is outside the grid"));
  SlicePngOptions negative;
  negative.scale = -1;
  EXPECT_TRUE(IsError(writeSlicePng(file, kGrid, sphereSample, {0, 1}, negative), kInvalid,
                      "slice scale must be >= 0 (got -1)"));
  EXPECT_TRUE(IsError(writeSlicePng(file, kGrid, VoxelSampler(), {0, 1}), kInvalid, "no field to sample"));
  SlicePngOptions huge;
  huge.scale = 1000;
  EXPECT_TRUE(IsError(writeSlicePng(file, kGrid, sphereSample, {0, 1}, huge), Status::Code::kResourceExhausted,
                      "64x64 voxels at scale 1000 exceeds the 16384-pixel edge limit"));
  EXPECT_FALSE(fs::exists(file));
  // An unwritable destination reports the OS error and leaves no temporary file.
  const std::string unwritable = (dir_ / "missing" / "x.png").string();
  const Status err = writeSlicePng(unwritable, kGrid, sphereSample, {0, 1});
  EXPECT_TRUE(IsError(err, Status::Code::kIoError, "cannot create a temporary file next to '" + unwritable + "'"));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 0);
}

}  // namespace
}  // namespace distband
