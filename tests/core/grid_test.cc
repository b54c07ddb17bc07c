// Tests for core/grid.h: brick addressing (linear brick indices follow the (z, y, x) order of the bricks' origins and
// brickOrigin inverts brickIndex, partial bricks at the far faces included) and per-axis spacing (world, index and
// unit space, windows, validation).
#include <cmath>

#include <gtest/gtest.h>

#include "core/grid.h"

namespace distband {
namespace {

TEST(GridTest, BrickIndexAndOriginRoundTripInZYXOrder) {
  const Grid grid({0, 0, 0}, 1, {20, 9, 17});  // 3 x 2 x 3 bricks, the last of each axis partial
  EXPECT_EQ(grid.brickDims(), (Coord{3, 2, 3}));
  EXPECT_EQ(grid.brickCount(), 18);
  int64_t expected = 0;
  for (int bz = 0; bz < 3; ++bz)
    for (int by = 0; by < 2; ++by)
      for (int bx = 0; bx < 3; ++bx) {
        EXPECT_EQ(grid.brickIndex({bx, by, bz}), expected);
        EXPECT_EQ(grid.brickOrigin(expected), (Coord{8 * bx, 8 * by, 8 * bz}));
        ++expected;
      }
}

TEST(GridTest, PerAxisSpacingMapsWorldIndexAndUnitSpace) {
  const Grid cubic({1, 2, 3}, 0.5, {4, 5, 6});
  EXPECT_TRUE(cubic.cubic());
  EXPECT_EQ(cubic.spacing(), (Vec3d{0.5, 0.5, 0.5}));
  EXPECT_EQ(cubic.axisScale(), (Vec3d{1, 1, 1}));
  EXPECT_EQ(cubic.maxAxisScale(), 1.0);
  EXPECT_EQ(cubic.unitsOf({2, 3, 4}), cubic.indexOf({2, 3, 4}));
  EXPECT_EQ(Grid({1, 2, 3}, Vec3d{0.5, 0.5, 0.5}, {4, 5, 6}), cubic);

  const Grid g({1, 2, 3}, Vec3d{0.5, 0.25, 1.5}, {10, 12, 14});
  EXPECT_FALSE(g.cubic());
  EXPECT_EQ(g.voxelSize(), 0.25);  // the unit: the smallest spacing
  EXPECT_EQ(g.axisScale(), (Vec3d{2, 1, 6}));
  EXPECT_EQ(g.maxAxisScale(), 6.0);
  EXPECT_EQ(g.worldOf({2, 4, 2}), (Vec3d{2, 3, 6}));
  EXPECT_EQ(g.indexOf({2, 3, 6}), (Vec3d{2, 4, 2}));
  EXPECT_EQ(g.unitsOf({2, 3, 6}), (Vec3d{4, 4, 12}));
  EXPECT_EQ(g.unitsOfIndex({2, 4, 2}), (Vec3d{4, 4, 12}));
  EXPECT_DOUBLE_EQ(g.diagonalWorld({2, 4, 2}), std::sqrt(1.0 + 1.0 + 9.0));
  const Grid w = g.window({{2, 4, 6}, {3, 3, 3}});
  EXPECT_EQ(w.spacing(), g.spacing());
  EXPECT_EQ(w.origin(), (Vec3d{2, 3, 12}));
  EXPECT_TRUE(g.validate().ok());
}

TEST(GridTest, ValidationNamesTheBadSpacing) {
  EXPECT_NE(Grid({0, 0, 0}, 0.0, {4, 4, 4}).validate().message().find("voxel size must be finite and > 0"),
            std::string::npos);
  EXPECT_NE(Grid({0, 0, 0}, Vec3d{1, -1, 1}, {4, 4, 4}).validate().message().find("spacing must be finite and > 0"),
            std::string::npos);
  EXPECT_NE(Grid({0, 0, 0}, Vec3d{1, 1, NAN}, {4, 4, 4}).validate().message().find("spacing must be finite"),
            std::string::npos);
  EXPECT_NE(Grid({0, 0, 0}, Vec3d{0.001, 1, 1.5}, {4, 4, 4}).validate().message().find("more than 1000 times"),
            std::string::npos);
  EXPECT_TRUE(Grid({0, 0, 0}, Vec3d{0.01, 1, 10}, {4, 4, 4}).validate().ok());
}

}  // namespace
}  // namespace distband
