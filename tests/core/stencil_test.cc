// Tests for core/stencil: link tables, lifespan coefficients and name parsing.
#include "core/stencil.h"

#include <cmath>
#include <cstdlib>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

namespace distband {
namespace {

int norm1(const Coord& c) { return std::abs(c.x) + std::abs(c.y) + std::abs(c.z); }

std::set<std::tuple<int, int, int>> linkSet(const Stencil& s) {
  std::set<std::tuple<int, int, int>> out;
  for (const Coord& c : s.links) out.insert({c.x, c.y, c.z});
  return out;
}

TEST(StencilTest, LinkCountsAndShapes) {
  const Stencil& c6 = Stencil::get(StencilKind::kCubic6);
  const Stencil& c18 = Stencil::get(StencilKind::kCubic18);
  const Stencil& c26 = Stencil::get(StencilKind::kCubic26);
  const Stencil& fcc = Stencil::get(StencilKind::kFcc12);
  EXPECT_EQ(c6.links.size(), 6u);
  EXPECT_EQ(c18.links.size(), 18u);
  EXPECT_EQ(c26.links.size(), 26u);
  for (const Coord& c : c6.links) EXPECT_EQ(norm1(c), 1);
  for (const Coord& c : c18.links) EXPECT_LE(norm1(c), 2);
  for (const Stencil* s : {&c6, &c18, &c26, &fcc}) {
    // No duplicates, no zero link, every link within the 3^3 block, and the set is symmetric.
    const auto set = linkSet(*s);
    EXPECT_EQ(set.size(), s->links.size());
    for (const Coord& c : s->links) {
      EXPECT_GT(norm1(c), 0);
      EXPECT_LE(std::max({std::abs(c.x), std::abs(c.y), std::abs(c.z)}), 1);
      EXPECT_TRUE(set.count({-c.x, -c.y, -c.z})) << "link (" << c.x << "," << c.y << "," << c.z << ") not mirrored";
    }
  }
  // FCC: the 12 face-diagonal links between even voxels, plus the 6 axial links that feed the odd half.
  int diagonal = 0, axial = 0;
  for (const Coord& c : fcc.links) {
    if (norm1(c) == 2) ++diagonal;
    if (norm1(c) == 1) ++axial;
  }
  EXPECT_EQ(diagonal, 12);
  EXPECT_EQ(axial, 6);
  EXPECT_EQ(fcc.links.size(), 18u);
}

TEST(StencilTest, FccPropagationParity) {
  const Stencil& fcc = Stencil::get(StencilKind::kFcc12);
  EXPECT_TRUE(fcc.fcc);
  EXPECT_TRUE(fcc.propagates({0, 0, 0}));
  EXPECT_TRUE(fcc.propagates({1, 1, 0}));
  EXPECT_TRUE(fcc.propagates({-1, 0, 1}));
  EXPECT_FALSE(fcc.propagates({1, 0, 0}));
  EXPECT_FALSE(fcc.propagates({1, 1, 1}));
  EXPECT_FALSE(fcc.propagates({-1, 0, 0}));
  for (StencilKind k : {StencilKind::kCubic6, StencilKind::kCubic18, StencilKind::kCubic26}) {
    EXPECT_FALSE(Stencil::get(k).fcc);
    EXPECT_TRUE(Stencil::get(k).propagates({1, 0, 0}));
    EXPECT_TRUE(Stencil::get(k).propagates({1, 1, 1}));
  }
}

TEST(StencilTest, LifespanCoefficients) {
  EXPECT_DOUBLE_EQ(Stencil::get(StencilKind::kCubic6).alpha, std::sqrt(3.0) - 1.0);
  EXPECT_DOUBLE_EQ(Stencil::get(StencilKind::kCubic18).alpha, std::sqrt(2.0) - 1.0);
  EXPECT_DOUBLE_EQ(Stencil::get(StencilKind::kCubic26).alpha, std::sqrt(3.0) - 1.0);
  EXPECT_DOUBLE_EQ(Stencil::get(StencilKind::kFcc12).alpha, std::sqrt(2.0) - 1.0);
  for (StencilKind k : {StencilKind::kCubic6, StencilKind::kCubic18, StencilKind::kCubic26, StencilKind::kFcc12})
    EXPECT_EQ(Stencil::get(k).kind, k);
}

TEST(StencilTest, NamesRoundTrip) {
  for (StencilKind k : {StencilKind::kCubic6, StencilKind::kCubic18, StencilKind::kCubic26, StencilKind::kFcc12}) {
    auto parsed = parseStencil(stencilName(k));
    ASSERT_TRUE(parsed.has_value()) << stencilName(k);
    EXPECT_EQ(*parsed, k);
  }
  EXPECT_FALSE(parseStencil("cubic27").has_value());
  EXPECT_FALSE(parseStencil("").has_value());
  EXPECT_FALSE(parseStencil("CUBIC26").has_value());
}

}  // namespace
}  // namespace distband
