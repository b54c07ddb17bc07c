// Tests for core/seeds/internal/boundary_curves: its turn rate bounds the winding number's gradient (measured by
// central differences of the brute-force winding number, tests/support/brute_mesh, which shares no code with core/)
// at points of the balls it is asked about, also where one curve's nearest distance says little (the centre of a
// round opening, curves run twice, several curves turning the winding number the same way); its distance is a lower
// bound on the distance to the curves; past the pieces' budget every ball counts as on a curve.
#include "core/seeds/internal/boundary_curves.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/mesh/triangle_mesh.h"
#include "core/mesh/winding_number.h"
#include "tests/support/brute_mesh.h"

namespace distband {
namespace {

using seeds_internal::BoundaryCurves;

// Flat washers (annuli between radii `inner` and `outer` around the z axis, all facing +z) at heights `z`: each has
// two boundary circles; with inner = 0 a disk (a fan around its centre, one circle).
TriangleMesh washers(double inner, double outer, const std::vector<double>& heights, int segments) {
  TriangleMesh m;
  for (double z : heights) {
    const auto base = uint32_t(m.vertices.size());
    if (inner == 0) {
      m.vertices.push_back({0, 0, z});
      for (int j = 0; j < segments; ++j) {
        const double a = 2 * std::numbers::pi * j / segments;
        m.vertices.push_back({outer * std::cos(a), outer * std::sin(a), z});
      }
      for (int j = 0; j < segments; ++j)
        m.triangles.push_back({base, base + 1 + uint32_t(j), base + 1 + uint32_t((j + 1) % segments)});
      continue;
    }
    for (int j = 0; j < segments; ++j) {
      const double a = 2 * std::numbers::pi * j / segments;
      m.vertices.push_back({inner * std::cos(a), inner * std::sin(a), z});
      m.vertices.push_back({outer * std::cos(a), outer * std::sin(a), z});
    }
    for (int j = 0; j < segments; ++j) {
      const uint32_t i0 = base + 2 * uint32_t(j), o0 = i0 + 1, i1 = base + 2 * uint32_t((j + 1) % segments),
                     o1 = i1 + 1;
      m.triangles.push_back({i0, o0, o1});
      m.triangles.push_back({i0, o1, i1});
    }
  }
  return m;
}

BoundaryCurves curvesOf(const TriangleMesh& mesh, uint64_t max_pieces = 1 << 20) {
  BoundaryCurves curves;
  curves.build(mesh.vertices, meshBoundaryChain(mesh.triangles), max_pieces);
  return curves;
}

// |grad w| at p by central differences of the exact winding number (p far from the surface against the step).
double gradientLength(const TriangleMesh& mesh, const Vec3d& p) {
  constexpr double h = 1e-4;
  const double gx = testing::bruteWinding(mesh, p + Vec3d{h, 0, 0}) - testing::bruteWinding(mesh, p - Vec3d{h, 0, 0});
  const double gy = testing::bruteWinding(mesh, p + Vec3d{0, h, 0}) - testing::bruteWinding(mesh, p - Vec3d{0, h, 0});
  const double gz = testing::bruteWinding(mesh, p + Vec3d{0, 0, h}) - testing::bruteWinding(mesh, p - Vec3d{0, 0, h});
  return std::sqrt(gx * gx + gy * gy + gz * gz) / (2 * h);
}

// Points of the ball (center, radius): its centre, then uniform ones.
std::vector<Vec3d> pointsIn(const Vec3d& center, double radius, int count, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Vec3d> points{center};
  while (int(points.size()) < count) {
    const Vec3d d{u(rng), u(rng), u(rng)};
    if (d.lengthSqr() <= 1) points.push_back(center + d * radius);
  }
  return points;
}

// The worst ratio of the exact gradient to the bound over the points of `balls` (each inside the ball of `reach`
// around `brick`) that lie off the surface; fails where the bound is below the gradient.
double worstShare(const TriangleMesh& mesh, const BoundaryCurves& curves, const Vec3d& brick, double reach,
                  const std::vector<std::pair<Vec3d, double>>& balls, std::mt19937& rng) {
  BoundaryCurves::Near near;
  curves.findNear(brick, reach, &near);
  double worst = 0;
  for (const auto& [c, r] : balls) {
    const double bound = curves.turnRate(near, c, r, std::numeric_limits<double>::infinity());
    if (!std::isfinite(bound)) continue;
    for (const Vec3d& p : pointsIn(c, r, 12, rng)) {
      if ((p - brick).length() > reach || testing::bruteDistance(mesh, p) < 1e-2) continue;
      const double g = gradientLength(mesh, p);
      EXPECT_LE(g, bound * (1 + 1e-6)) << "at (" << p.x << ", " << p.y << ", " << p.z << ") in the ball of radius "
                                       << r;
      worst = std::max(worst, g / bound);
    }
  }
  return worst;
}

// At the centre of a round opening every piece of the rim turns the winding number the same way: the gradient is
// 1 / (2 B) for a rim of radius B, more than the nearest curve's straight-edge figure allows (1 / (pi B)).
TEST(BoundaryCurvesTest, TheTurnRateBoundsTheGradientAtTheCentreOfARoundOpening) {
  constexpr double B = 40;
  const TriangleMesh disk = washers(0, B, {0}, 96);
  const BoundaryCurves curves = curvesOf(disk);
  const Vec3d p{0, 0, 0.5};  // just off the disk's centre
  BoundaryCurves::Near near;
  curves.findNear(p, 2, &near);
  const double bound = curves.turnRate(near, p, 0.5, std::numeric_limits<double>::infinity());
  const double exact = gradientLength(disk, p);
  std::printf(
      "[curves] round rim of radius %.0f: gradient %.5f (1 / 2B = %.5f), bound %.5f, nearest-curve figure "
      "1 / (pi B) %.5f\n",
      B, exact, 1 / (2 * B), bound, 1 / (std::numbers::pi * (B - 0.5)));
  EXPECT_NEAR(exact, 1 / (2 * B), 1e-3 / B);
  EXPECT_GE(bound, exact);
  EXPECT_LE(bound, 1.5 * exact) << "the bound should stay close where the curve is round";
  EXPECT_LT(1 / (std::numbers::pi * (B - 0.5)), exact) << "the case the sum of the pieces exists for";
}

// A rim run twice (two copies of the disk: the chain's edges have net 2) turns the winding number twice as fast.
TEST(BoundaryCurvesTest, ACurveRunTwiceCountsTwice) {
  TriangleMesh twice = washers(0, 40, {0}, 96);
  const size_t n = twice.triangles.size();
  for (size_t t = 0; t < n; ++t) twice.triangles.push_back(twice.triangles[t]);
  const BoundaryCurves curves = curvesOf(twice);
  std::mt19937 rng(7);
  const Vec3d brick{10, -5, 3};
  const double share = worstShare(twice, curves, brick, 6, {{brick, 6}, {brick + Vec3d{2, 1, -1}, 2}}, rng);
  EXPECT_GT(share, 0.3) << "the bound should not be loose by more than ~3x here";
}

// Several washers stacked along their common hole: on its axis every inner rim turns the winding number the same
// way. Balls on the axis, near the rims and far outside, the bound for a brick's ball and for smaller balls inside
// it (a certificate's box, a voxel's ball), with the pieces few (brute-force groups) and many (cells).
TEST(BoundaryCurvesTest, TheTurnRateBoundsTheGradientAroundAStackOfWashers) {
  for (int segments : {24, 400}) {
    SCOPED_TRACE(segments);
    const TriangleMesh stack = washers(30, 60, {-12, -6, 0, 6, 12}, segments);
    const BoundaryCurves curves = curvesOf(stack);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1, 1);
    double worst = 0;
    for (const Vec3d& brick :
         {Vec3d{0, 0, 3}, Vec3d{0, 0, 15}, Vec3d{25, 3, 3}, Vec3d{45, 0, 9}, Vec3d{0, 80, 0}, Vec3d{-20, 20, -20}}) {
      std::vector<std::pair<Vec3d, double>> balls{{brick, 6}};
      for (int k = 0; k < 6; ++k)
        balls.push_back({brick + Vec3d{u(rng), u(rng), u(rng)} * 3, 1 + 2 * std::abs(u(rng))});
      worst = std::max(worst, worstShare(stack, curves, brick, 6, balls, rng));
    }
    std::printf("[curves] stack of washers, %d segments: the gradient reaches %.2f of the bound\n", segments, worst);
    EXPECT_GT(worst, 0.1);
  }
}

// On the axis of a stack of wide washers the gradient is several times one rim's 1 / (2 B) (their outer rims, far
// away, turn it the other way a little); the bound follows it.
TEST(BoundaryCurvesTest, CurvesTurningTheSameWayAddUp) {
  constexpr double B = 30;
  const TriangleMesh stack = washers(B, 300, {-12, -6, 0, 6, 12}, 96);
  const BoundaryCurves curves = curvesOf(stack);
  const Vec3d p{0, 0, 3};
  const double exact = gradientLength(stack, p);
  BoundaryCurves::Near near;
  curves.findNear(p, 1, &near);
  const double bound = curves.turnRate(near, p, 0.5, std::numeric_limits<double>::infinity());
  std::printf("[curves] stack of 5 washers, axis: gradient %.5f (one rim 1 / 2B = %.5f), bound %.5f\n", exact,
              1 / (2 * B), bound);
  EXPECT_GT(exact, 3 / (2 * B));
  EXPECT_GE(bound, exact);
}

// The distance bound is a lower bound on the distance to the curves (the washers' rims, sampled finely).
TEST(BoundaryCurvesTest, TheDistanceIsALowerBound) {
  for (int segments : {24, 400}) {
    SCOPED_TRACE(segments);
    const TriangleMesh stack = washers(30, 60, {-12, 0, 12}, segments);
    const BoundaryCurves curves = curvesOf(stack);
    std::vector<Vec3d> rim;  // points on the rims' edges
    for (const auto& e : meshBoundaryChain(stack.triangles))
      for (int k = 0; k <= 50; ++k)
        rim.push_back(stack.vertices[e.a] + (stack.vertices[e.b] - stack.vertices[e.a]) * (k / 50.0));
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-80, 80);
    for (int trial = 0; trial < 200; ++trial) {
      const Vec3d brick{u(rng), u(rng), u(rng) / 4};
      BoundaryCurves::Near near;
      curves.findNear(brick, 6, &near);
      const double r = 2;
      const Vec3d c = brick + Vec3d{1, -2, 1};
      const double bound = curves.distance(near, c, r);
      double nearest = std::numeric_limits<double>::infinity();
      for (const Vec3d& q : rim) nearest = std::min(nearest, (q - c).length());
      EXPECT_LE(bound, std::max(0.0, nearest - r) + 1e-9);
      EXPECT_GE(bound, std::max(0.0, nearest - r) - 0.5)
          << "the distance bound should be tight when the curves are near";
    }
  }
}

// Past the budget of pieces nothing is kept: every ball counts as on a curve.
TEST(BoundaryCurvesTest, PastTheBudgetTheCurvesAreEverywhere) {
  const BoundaryCurves curves = curvesOf(washers(30, 60, {0}, 96), 10);
  EXPECT_TRUE(curves.everywhere());
  BoundaryCurves::Near near;
  curves.findNear({500, 500, 500}, 6, &near);
  EXPECT_EQ(curves.distance(near, {500, 500, 500}, 1), 0);
  EXPECT_TRUE(std::isinf(curves.turnRate(near, {500, 500, 500}, 1, 1)));
}

// A closed mesh has no curves: the winding number does not turn off it.
TEST(BoundaryCurvesTest, AClosedMeshHasNoTurn) {
  const BoundaryCurves curves = curvesOf(testing::makeSphereMesh({0, 0, 0}, 20, 12, 24));
  BoundaryCurves::Near near;
  curves.findNear({3, 0, 0}, 6, &near);
  EXPECT_EQ(curves.turnRate(near, {3, 0, 0}, 6, 1), 0);
  EXPECT_EQ(curves.distance(near, {3, 0, 0}, 6), BoundaryCurves::kFar);
}

}  // namespace
}  // namespace distband
