// Tests for core/mesh/winding_number: the hierarchy's exactly summed triangles (a product of complex numbers with its
// turns counted, one atan2 per query) against the sum of each triangle's atan2, on points everywhere around open and
// closed meshes, on their surfaces, vertices and planes, and inside (several full turns).
#include "core/mesh/winding_number.h"

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "core/mesh/triangle_mesh.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_mesh.h"

namespace distband {
namespace {

std::vector<std::array<Vec3d, 3>> trianglesOf(const TriangleMesh& mesh) {
  std::vector<std::array<Vec3d, 3>> tris;
  for (const auto& t : mesh.triangles) tris.push_back({mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]});
  return tris;
}

TEST(WindingNumberTest, TheComplexProductEqualsTheSumOfAtan2s) {
  for (const char* name : {"teapot.obj", "bunny.obj", "fandisk.off"}) {
    SCOPED_TRACE(name);
    TriangleMesh mesh;
    ASSERT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/" + name, &mesh, nullptr)));
    // beta = infinity opens every cluster: query() sums every triangle through the product.
    const WindingNumber all(trianglesOf(mesh), std::numeric_limits<double>::infinity());
    Vec3d lo = mesh.vertices[0], hi = lo;
    for (const Vec3d& v : mesh.vertices) {
      lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
      hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    }
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-0.2, 1.2);
    auto check = [&](const Vec3d& p) {
      const double want = all.exact(p), got = all.query(p);
      ASSERT_NEAR(got, want, 1e-9) << p.x << "," << p.y << "," << p.z;
    };
    for (int i = 0; i < 300; ++i)
      check({lo.x + u(rng) * (hi.x - lo.x), lo.y + u(rng) * (hi.y - lo.y), lo.z + u(rng) * (hi.z - lo.z)});
    // On the surface: vertices, edge midpoints, centroids, and just off them along the normal.
    for (size_t t = 0; t < mesh.triangles.size(); t += 37) {
      const auto& tri = mesh.triangles[t];
      const Vec3d a = mesh.vertices[tri[0]], b = mesh.vertices[tri[1]], c = mesh.vertices[tri[2]];
      const Vec3d n = (b - a).cross(c - a);
      const double eps = 1e-6 * (hi - lo).length() / std::max(n.length(), 1e-300);
      for (const Vec3d& p : {a, (a + b) * 0.5, (a + b + c) * (1.0 / 3.0)}) {
        check(p);
        check(p + n * eps);
        check(p - n * eps);
      }
    }
  }
}

TEST(WindingNumberTest, InsideAClosedMeshIsOneAndOutsideZero) {
  TriangleMesh mesh;
  ASSERT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/bunny.obj", &mesh, nullptr)));
  const WindingNumber wn(trianglesOf(mesh));
  Vec3d lo = mesh.vertices[0], hi = lo;
  for (const Vec3d& v : mesh.vertices) {
    lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
    hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
  }
  // Within the first-order hierarchy's error (dipoles beyond beta = 2 cluster radii: a few hundredths), and four
  // full turns (4 pi of solid angle) counted inside.
  const Vec3d centre = (lo + hi) * 0.5;
  EXPECT_NEAR(testing::bruteWinding(mesh, centre), 1.0, 1e-9);
  EXPECT_NEAR(wn.query(centre), 1.0, 0.05);
  EXPECT_NEAR(wn.query(hi + (hi - lo)), 0.0, 0.05);
}

}  // namespace
}  // namespace distband
