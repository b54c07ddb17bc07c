// Tests for core/grid.h's brick addressing: linear brick indices follow the (z, y, x) order of the bricks' origins and
// brickOrigin inverts brickIndex, partial bricks at the far faces included.
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

}  // namespace
}  // namespace distband
