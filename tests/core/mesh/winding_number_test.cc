// Tests for core/mesh/winding_number: the hierarchy's exactly summed triangles (a product of complex numbers with its
// turns counted, one atan2 per query) against the sum of each triangle's atan2, on points everywhere around open and
// closed meshes, on their surfaces, vertices and planes, and inside (several full turns).
#include "core/mesh/winding_number.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "core/mesh/triangle_mesh.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_mesh.h"

namespace distband {
namespace {

void boundsOf(const TriangleMesh& mesh, Vec3d* lo, Vec3d* hi) {
  *lo = *hi = mesh.vertices[0];
  for (const Vec3d& v : mesh.vertices) {
    *lo = {std::min(lo->x, v.x), std::min(lo->y, v.y), std::min(lo->z, v.z)};
    *hi = {std::max(hi->x, v.x), std::max(hi->y, v.y), std::max(hi->z, v.z)};
  }
}

std::vector<std::array<Vec3d, 3>> trianglesOf(const TriangleMesh& mesh) {
  std::vector<std::array<Vec3d, 3>> tris;
  for (const auto& t : mesh.triangles) tris.push_back({mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]});
  return tris;
}

TEST(WindingNumberTest, NearSumsEqualTheExactSum) {
  for (const char* name : {"teapot.obj", "bunny.obj", "fandisk.off"}) {
    SCOPED_TRACE(name);
    TriangleMesh mesh;
    ASSERT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/" + name, &mesh, nullptr)));
    // beta = infinity opens every cluster: query() sums every triangle's solid angle as a near one, in single-precision
    // lanes (within 3.2e-7 of the double-precision sum here) or, on the surface and just off it, in double.
    const WindingNumber all(trianglesOf(mesh), std::numeric_limits<double>::infinity());
    Vec3d lo, hi;
    boundsOf(mesh, &lo, &hi);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-0.2, 1.2);
    auto check = [&](const Vec3d& p) {
      const double want = all.exact(p), got = all.query(p);
      ASSERT_NEAR(got, want, 1e-6) << p.x << "," << p.y << "," << p.z;
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
  Vec3d lo, hi;
  boundsOf(mesh, &lo, &hi);
  // Within the first-order hierarchy's error (dipoles beyond beta = 2 cluster radii: a few hundredths), and four
  // full turns (4 pi of solid angle) counted inside.
  const Vec3d centre = (lo + hi) * 0.5;
  EXPECT_NEAR(testing::bruteWinding(mesh, centre), 1.0, 1e-9);
  EXPECT_NEAR(wn.query(centre), 1.0, 0.05);
  EXPECT_NEAR(wn.query(hi + (hi - lo)), 0.0, 0.05);
}

// The teapot, or the bunny with every 40th triangle removed (holes), scaled to a 500-unit box (a 512^3 grid's index
// frame); empty if the file does not load.
std::vector<std::array<Vec3d, 3>> openMeshIn500Box(const std::string& name) {
  TriangleMesh mesh;
  if (!IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/" + name, &mesh, nullptr))) return {};
  Vec3d lo, hi;
  boundsOf(mesh, &lo, &hi);
  const double scale = 500.0 / std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  std::vector<std::array<Vec3d, 3>> tris;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    if (name == "bunny.obj" && t % 40 == 0) continue;
    const auto& tri = mesh.triangles[t];
    tris.push_back({(mesh.vertices[tri[0]] - lo) * scale, (mesh.vertices[tri[1]] - lo) * scale,
                    (mesh.vertices[tri[2]] - lo) * scale});
  }
  return tris;
}

// A random point of a random triangle, moved by up to 3 units along each axis.
Vec3d nearSurface(const std::vector<std::array<Vec3d, 3>>& tris, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0, 1), offset(-3, 3);
  const auto& t = tris[rng() % tris.size()];
  double a = u(rng), b = u(rng);
  if (a + b > 1) a = 1 - a, b = 1 - b;
  return t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b + Vec3d{offset(rng), offset(rng), offset(rng)};
}

// The hierarchy's error near open meshes, where signs are decided: points within 3 units of the surface of the teapot
// and of a bunny with every 40th triangle removed, both scaled to a 500-unit box (a 512^3 grid's index frame), against
// the exact sum. query() stays within the 0.03 the signs allow for it, coarseQuery() and roughQuery() within half the
// 0.1 and 0.3 they allow for them (core/seeds/mesh_sign.cc).
TEST(WindingNumberTest, EachQueryStaysWithinItsErrorNearOpenMeshes) {
  for (const char* name : {"teapot.obj", "bunny.obj"}) {
    SCOPED_TRACE(name);
    const std::vector<std::array<Vec3d, 3>> tris = openMeshIn500Box(name);
    ASSERT_FALSE(tris.empty());
    const WindingNumber wn(tris);
    std::mt19937 rng(5);
    double query_error = 0, coarse_error = 0, rough_error = 0;
    for (int i = 0; i < 3000; ++i) {
      const Vec3d p = nearSurface(tris, rng);
      const double exact = wn.exact(p);
      query_error = std::max(query_error, std::abs(wn.query(p) - exact));
      coarse_error = std::max(coarse_error, std::abs(wn.coarseQuery(p) - exact));
      rough_error = std::max(rough_error, std::abs(wn.roughQuery(p) - exact));
    }
    std::printf("[winding] %s: largest error query %.4f, coarse %.4f, rough %.4f\n", name, query_error, coarse_error,
                rough_error);
    EXPECT_LT(query_error, 0.03);
    EXPECT_LT(coarse_error, 0.05);
    EXPECT_GT(coarse_error, 0) << "the coarse query approximates";
    EXPECT_LT(rough_error, 0.15);
    EXPECT_GT(rough_error, coarse_error) << "the rough query approximates more";
  }
}

// A plan (WindingNumber::plan) made for a brick's ball reads, at every point of the ball, clusters that pass the tier's
// test there: its values stay within the bounds of each tier above, and the rough plan is no worse than the rough
// query at the same points. Same meshes and scale as above; balls of a brick's radius (8^3 voxels) centred within 3
// voxels of the surface, ten points in each.
TEST(WindingNumberTest, PlansStayWithinTheirTiersErrorInTheirBall) {
  for (const char* name : {"teapot.obj", "bunny.obj"}) {
    SCOPED_TRACE(name);
    const std::vector<std::array<Vec3d, 3>> tris = openMeshIn500Box(name);
    ASSERT_FALSE(tris.empty());
    const WindingNumber wn(tris);
    const double radius = 3.5 * std::sqrt(3.0);
    std::mt19937 rng(9);
    std::uniform_real_distribution<double> in_ball(-1, 1);
    double error[3] = {}, rough_query_error = 0;
    WindingNumber::Plan plans[3];
    const WindingNumber::Tier tiers[3] = {WindingNumber::Tier::kFine, WindingNumber::Tier::kCoarse,
                                          WindingNumber::Tier::kRough};
    for (int box = 0; box < 100; ++box) {
      const Vec3d center = nearSurface(tris, rng);
      for (int k = 0; k < 3; ++k) wn.plan(center, radius, tiers[k], &plans[k]);
      EXPECT_LE(plans[2].far.size() + plans[2].near.size(), plans[0].far.size() + plans[0].near.size());
      for (int i = 0; i < 10; ++i) {
        Vec3d p;
        do p = {in_ball(rng), in_ball(rng), in_ball(rng)};
        while (p.lengthSqr() > 1);
        p = center + p * radius;
        const double exact = wn.exact(p);
        for (int k = 0; k < 3; ++k) error[k] = std::max(error[k], std::abs(wn.planned(plans[k], p) - exact));
        rough_query_error = std::max(rough_query_error, std::abs(wn.roughQuery(p) - exact));
      }
    }
    std::printf("[winding] %s plans: largest error fine %.4f, coarse %.4f, rough %.4f (rough query %.4f)\n", name,
                error[0], error[1], error[2], rough_query_error);
    EXPECT_LT(error[0], 0.03);
    EXPECT_LT(error[1], 0.05);
    EXPECT_LT(error[2], 0.15);
    EXPECT_LE(error[2], rough_query_error);
  }
}

// A plan made for a ball of radius 0 at p lists the clusters its tier's query takes at p, and its evaluation (far
// clusters eight lanes to a block, near leaves two to a block, an odd one out alone) gives the query's value up to
// single precision: points near the surface, on vertices, edges and faces (unsure lanes), of both meshes; near-leaf
// counts odd and even, leaves of 2-4 triangles.
TEST(WindingNumberTest, APlanAtAPointGivesItsTiersQuery) {
  for (const char* name : {"teapot.obj", "bunny.obj"}) {
    SCOPED_TRACE(name);
    const std::vector<std::array<Vec3d, 3>> tris = openMeshIn500Box(name);
    ASSERT_FALSE(tris.empty());
    const WindingNumber wn(tris);
    std::mt19937 rng(5);
    std::vector<Vec3d> points;
    for (int i = 0; i < 300; ++i) points.push_back(nearSurface(tris, rng));
    for (size_t t = 0; t < tris.size(); t += 53)
      points.insert(points.end(), {tris[t][0], (tris[t][0] + tris[t][1]) * 0.5,
                                   (tris[t][0] + tris[t][1] + tris[t][2]) * (1.0 / 3.0)});
    const struct {
      WindingNumber::Tier tier;
      double (WindingNumber::*query)(const Vec3d&) const;
    } tiers[] = {{WindingNumber::Tier::kFine, &WindingNumber::query},
                 {WindingNumber::Tier::kCoarse, &WindingNumber::coarseQuery},
                 {WindingNumber::Tier::kRough, &WindingNumber::roughQuery}};
    int odd = 0, even = 0;
    WindingNumber::Plan plan;
    for (const auto& tier : tiers)
      for (const Vec3d& p : points) {
        wn.plan(p, 0, tier.tier, &plan);
        (plan.near.size() % 2 ? odd : even) += 1;
        ASSERT_NEAR(wn.planned(plan, p), (wn.*tier.query)(p), 2e-5) << p.x << "," << p.y << "," << p.z;
      }
    EXPECT_GT(odd, 0);
    EXPECT_GT(even, 0);
  }
}

// The boundary fans (core/mesh/winding_number.h: boundaryFans) have the mesh's boundary, so the mesh's exact winding
// number minus theirs is an integer everywhere off both (the brute oracle of tests/support for both sums). Meshes: the
// teapot (open, three parts), a bunny with every 40th face removed, a closed bunny (no boundary, no fans), an open
// square with a flipped patch (edges run twice the same way: net 2), a box without its top whose rim's centroid is a
// lattice point (the fan's apex must be moved off it), and a fin of three faces on one edge (non-manifold).
TEST(WindingNumberTest, BoundaryFansDifferFromTheMeshByAnInteger) {
  std::vector<std::pair<std::string, TriangleMesh>> meshes;
  for (const char* name : {"teapot.obj", "bunny.obj"}) {
    TriangleMesh mesh;
    ASSERT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/" + name, &mesh, nullptr)));
    meshes.emplace_back(name, mesh);
    if (std::string(name) == "bunny.obj") {
      TriangleMesh holed = mesh;
      holed.triangles.clear();
      for (size_t t = 0; t < mesh.triangles.size(); ++t)
        if (t % 40 != 0) holed.triangles.push_back(mesh.triangles[t]);
      meshes.emplace_back("bunny, holes", holed);
    }
  }
  TriangleMesh disk;  // a 9 x 9 lattice square at z = 8, as 128 triangles
  for (int y = 0; y <= 8; ++y)
    for (int x = 0; x <= 8; ++x) disk.vertices.push_back({double(x), double(y), 8});
  for (uint32_t y = 0; y < 8; ++y)
    for (uint32_t x = 0; x < 8; ++x) {
      const uint32_t v = 9 * y + x;
      disk.triangles.push_back({v, v + 1, v + 10});
      disk.triangles.push_back({v, v + 10, v + 9});
    }
  TriangleMesh strip = disk;  // the square with its middle column of squares flipped
  for (size_t t = 0; t < strip.triangles.size(); ++t)
    if ((t / 2) % 8 == 4) std::swap(strip.triangles[t][1], strip.triangles[t][2]);
  meshes.emplace_back("flipped patch", strip);
  // A box of side 8 on the lattice without its top: its rim's centroid (4, 4, 8) is a lattice point, and lattice
  // points of the open top lie on the lines from it to the rim's corners.
  TriangleMesh box = testing::makeBoxMesh({0, 0, 0}, {8, 8, 8});
  std::erase_if(box.triangles, [&](const auto& t) {
    return box.vertices[t[0]].z == 8 && box.vertices[t[1]].z == 8 && box.vertices[t[2]].z == 8;
  });
  meshes.emplace_back("open box", box);
  TriangleMesh fin;
  fin.vertices = {{0, 0, 0}, {0, 0, 4}, {3, 0, 1}, {-2, 2, 1}, {-1, -3, 2}};
  fin.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  meshes.emplace_back("fin", fin);
  for (const auto& entry : meshes) {
    const std::string& name = entry.first;  // not a structured binding: lambdas below read it (clang 14)
    const TriangleMesh& mesh = entry.second;
    SCOPED_TRACE(name);
    const std::vector<ChainEdge> chain = meshBoundaryChain(mesh.triangles);
    const std::vector<std::array<Vec3d, 3>> fans = boundaryFans(mesh.vertices, chain);
    int64_t net = 0, twice_one_way = 0;
    for (const ChainEdge& e : chain) net += std::abs(e.net), twice_one_way += e.uses == 2;
    EXPECT_GE(fans.size(), size_t(net));
    EXPECT_LE(fans.size(), size_t(net) * 3 / 2 + 3);
    if (name == "bunny.obj") {
      EXPECT_TRUE(chain.empty()) << "a closed mesh has no boundary";
    } else if (name == "flipped patch") {
      EXPECT_EQ(twice_one_way, 16) << "the patch's two seams of 8 edges";
    } else if (name == "fin") {
      EXPECT_EQ(chain.size(), 7u) << "the shared edge (3 uses) and the six free ones";
    } else if (name == "open box") {
      EXPECT_EQ(chain.size(), 4u) << "the rim";
    }
    TriangleMesh fan_mesh;
    for (const auto& t : fans) {
      const auto v = uint32_t(fan_mesh.vertices.size());
      fan_mesh.vertices.insert(fan_mesh.vertices.end(), t.begin(), t.end());
      fan_mesh.triangles.push_back({v, v + 1, v + 2});
    }
    Vec3d lo, hi;
    boundsOf(mesh, &lo, &hi);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-0.2, 1.2);
    int fractional = 0;
    auto check = [&](const Vec3d& p) {
      const double w = testing::bruteWinding(mesh, p), diff = w - testing::bruteWinding(fan_mesh, p);
      ASSERT_NEAR(diff, std::round(diff), 1e-9) << p.x << "," << p.y << "," << p.z << " w " << w;
      fractional += std::abs(w - std::round(w)) > 0.01;
    };
    for (int i = 0; i < 400; ++i)
      check({lo.x + u(rng) * (hi.x - lo.x), lo.y + u(rng) * (hi.y - lo.y), lo.z + u(rng) * (hi.z - lo.z)});
    for (int z = 7; z <= 9 && (name == "flipped patch" || name == "open box"); ++z)  // the lattice near the square
      for (int y = -1; y <= 9; ++y)
        for (int x = -1; x <= 9; ++x) {
          if (z == 8 && name == "flipped patch") continue;  // on the sheet
          const bool on_side = (x == 0 || x == 8 || y == 0 || y == 8) && x >= 0 && x <= 8 && y >= 0 && y <= 8;
          if (name == "open box" && on_side && z <= 8) continue;  // on the box's sides or rim
          check({double(x), double(y), double(z)});
        }
    if (!chain.empty()) {
      EXPECT_GT(fractional, 40) << "points where the winding number is not an integer";
    }
    // The signs read the fans' winding number with query() and allow it the finest tier's error, 0.03: within 3 units
    // of the boundary of the mesh scaled to a 500-unit box (a 512^3 grid's index frame), it stays within half that.
    if (chain.empty()) continue;
    const double scale = 500.0 / std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    std::vector<Vec3d> scaled(mesh.vertices.size());
    for (size_t v = 0; v < scaled.size(); ++v) scaled[v] = (mesh.vertices[v] - lo) * scale;
    const WindingNumber scaled_fans(boundaryFans(scaled, chain));
    std::uniform_real_distribution<double> along(0, 1), offset(-3, 3);
    double fan_error = 0;
    for (int i = 0; i < 500; ++i) {
      const ChainEdge& e = chain[rng() % chain.size()];
      const Vec3d p =
          scaled[e.a] + (scaled[e.b] - scaled[e.a]) * along(rng) + Vec3d{offset(rng), offset(rng), offset(rng)};
      fan_error = std::max(fan_error, std::abs(scaled_fans.query(p) - scaled_fans.exact(p)));
    }
    std::printf("[winding] %s: the fans' query within %.4f of their exact sum near the boundary\n", name.c_str(),
                fan_error);
    EXPECT_LT(fan_error, 0.015);
  }
}

}  // namespace
}  // namespace distband
