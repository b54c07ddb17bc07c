// Messy meshes (issue 21): what distband returns for the meshes people actually have — soups, duplicated faces,
// flipped patches, overlapping parts, non-manifold edges, T-junctions and cracks, zero-area and needle triangles,
// nested shells, an open disk, a cup. Every mesh is generated here and goes the user's way: validateMesh (welds,
// drops degenerate faces, repairs orientation), the sign `auto` resolved on its report (resolveSignMethod), the
// default mode and stencil, a band limited to 3 voxels. The contract (docs/algorithm.md, "Messy meshes"): the sign
// is that of the exact generalized winding number of the validated mesh (inside where w > 1/2) on >= 99.99 % of the
// delivered voxels where that number is decided (|w - 1/2| > 0.05), and |field| is the distance to the nearest
// triangle within 0.1 voxel (max) and 0.002 voxel (mean). The oracle is tests/support/brute_mesh (no code shared
// with core/).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include "core/band/band_engine.h"
#include "core/io/dense_field.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/mesh_sign.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

using testing::bruteDistance;
using testing::bruteWinding;
using testing::makeBoxMesh;
using testing::makeSphereMesh;
using testing::makeTorusMesh;

constexpr double kLimitVoxels = 3;         // the band: 3 voxels on each side of the surface
constexpr int kResolution = 56;            // voxels along the longest side: the brute force stays cheap
constexpr int kPadding = 4;                // voxels around the mesh (of the 56): more than the limit, no clipping
constexpr double kUndecided = 0.05;        // |w - 1/2| at most this: the winding number does not decide the side
constexpr double kOnSurfaceVoxels = 1e-3;  // closer to the surface, a voxel's sign is not checked
constexpr double kSignAgreement = 0.9999;
constexpr double kMaxErrorVoxels = 0.1, kMeanErrorVoxels = 0.002;

// A mesh as the user gets it: validated, its sign resolved (auto unless asked), its band field.
struct Computed {
  TriangleMesh mesh;  // validated (welded, degenerate faces dropped, orientation repaired)
  MeshReport report;
  SignMethod sign = SignMethod::kAuto;
  std::string reason;
  Grid grid;
  std::vector<float> field;  // dense, NaN where nothing was delivered
  float at(const Coord& c) const { return field[size_t(grid.denseIndex(c))]; }
};

Grid gridOf(const TriangleMesh& mesh, int resolution = kResolution, int padding = kPadding) {
  MeshGridOptions go;
  go.resolution = resolution;
  go.padding_voxels = padding;
  Grid grid;
  EXPECT_TRUE(IsOk(gridForMesh(mesh, go, {}, &grid)));
  return grid;
}

Computed compute(TriangleMesh raw, SignMethod requested = SignMethod::kAuto,
                 std::optional<StencilKind> stencil = std::nullopt, int resolution = kResolution,
                 double limit_voxels = kLimitVoxels, int padding = kPadding) {
  Computed c;
  EXPECT_TRUE(IsOk(validateMesh(&raw, &c.report)));
  c.mesh = std::move(raw);
  c.sign = resolveSignMethod(requested, c.report, &c.reason);
  c.grid = gridOf(c.mesh, resolution, padding);
  MeshSeedOptions so;
  so.sign = c.sign;
  so.limit_voxels = limit_voxels;
  Seeds seeds;
  EXPECT_TRUE(IsOk(makeMeshSeeds(c.grid, c.mesh, so, &seeds)));
  BandOptions eo;  // exact mode, the default stencil unless asked
  eo.stencil = stencil;
  eo.limit_world = limit_voxels * c.grid.voxelSize();
  DenseField field(c.grid, std::numeric_limits<float>::quiet_NaN());
  computeBandField(c.grid, seeds, eo, [&](SegmentBricks&& s) { field.add(s); });
  c.field = std::move(field.values());
  return c;
}

struct Figures {
  int64_t delivered = 0, checked = 0, off_surface = 0, decided = 0, wrong_signs = 0;
  int64_t fractional = 0;  // off the surface with w more than 0.01 from an integer (holes, cracks, open sheets)
  double max_error = 0, mean_error = 0;  // | |field| - exact distance |, in voxels
};

// Checks the delivered voxels of `c` against brute force: all of them when that is cheap, else every k-th voxel of
// every brick (each brick's first delivered voxel included), so the whole band is covered. `winding_of` is the mesh
// whose exact winding number decides the sign (the validated one unless a case says otherwise).
Figures checkAgainstBruteForce(const Computed& c, const TriangleMesh* winding_of = nullptr) {
  const TriangleMesh& wmesh = winding_of ? *winding_of : c.mesh;
  const Coord d = c.grid.dims(), bricks = c.grid.brickDims();
  std::vector<Coord> voxels;
  std::vector<size_t> brick_start;
  for (int bz = 0; bz < bricks.z; ++bz)
    for (int by = 0; by < bricks.y; ++by)
      for (int bx = 0; bx < bricks.x; ++bx) {
        brick_start.push_back(voxels.size());
        for (int z = bz * kBrickSize; z < std::min(d.z, (bz + 1) * kBrickSize); ++z)
          for (int y = by * kBrickSize; y < std::min(d.y, (by + 1) * kBrickSize); ++y)
            for (int x = bx * kBrickSize; x < std::min(d.x, (bx + 1) * kBrickSize); ++x)
              if (!std::isnan(c.at({x, y, z}))) voxels.push_back({x, y, z});
      }
  brick_start.push_back(voxels.size());
  Figures f;
  f.delivered = int64_t(voxels.size());
  // Budget: ~6e7 triangle visits for each oracle (a few seconds on two cores).
  const double work = double(voxels.size()) * double(std::max(c.mesh.triangles.size(), wmesh.triangles.size()));
  const size_t stride = std::max<size_t>(1, size_t(std::ceil(work / 6e7)));
  std::vector<Coord> checked;
  for (size_t b = 0; b + 1 < brick_start.size(); ++b)
    for (size_t i = brick_start[b]; i < brick_start[b + 1]; i += stride) checked.push_back(voxels[i]);
  std::vector<double> error(checked.size());
  // 0 on the surface, 3 undecided, 1 agrees, 2 wrong; | 4: w is not near an integer.
  std::vector<int8_t> verdict(checked.size());
  const double h = c.grid.voxelSize();
  tbb::parallel_for(size_t(0), checked.size(), [&](size_t i) {
    const Vec3d p = c.grid.worldOf(checked[i]);
    const float got = c.at(checked[i]);
    const double distance = bruteDistance(c.mesh, p);
    error[i] = std::abs(std::abs(double(got)) - distance) / h;
    // On the surface (the box's faces lie on voxel planes) the value is 0 and its sign carries nothing.
    if (c.sign == SignMethod::kUnsigned || distance <= kOnSurfaceVoxels * h) return;
    verdict[i] = 3;
    const double w = bruteWinding(wmesh, p);
    if (std::abs(w - std::round(w)) > 0.01) verdict[i] |= 4;
    if (std::abs(w - 0.5) > kUndecided) verdict[i] = int8_t((verdict[i] & 4) | ((w > 0.5) == (got < 0) ? 1 : 2));
  });
  f.checked = int64_t(checked.size());
  for (size_t i = 0; i < checked.size(); ++i) {
    f.max_error = std::max(f.max_error, error[i]);
    f.mean_error += error[i];
    const int v = verdict[i] & 3;
    f.off_surface += v > 0;
    f.decided += v == 1 || v == 2;
    f.wrong_signs += v == 2;
    f.fractional += (verdict[i] & 4) != 0;
  }
  f.mean_error /= std::max<double>(1, double(checked.size()));
  return f;
}

// The contract's figures for one case, printed for docs/algorithm.md. `check_max_error` false: the caller checks
// the max distance error its own way.
void expectContract(const std::string& name, const Computed& c, const Figures& f, bool check_max_error = true) {
  std::printf("[messy] %-28s sign %s (%s); %s\n", name.c_str(), std::string(signMethodName(c.sign)).c_str(),
              c.reason.c_str(), c.report.summary().c_str());
  std::printf(
      "[messy] %-28s delivered %lld, checked %lld (%lld off the surface, %lld with fractional w), decided "
      "%lld, wrong signs %lld, distance error max %.5f mean %.6f voxel\n",
      name.c_str(), (long long)f.delivered, (long long)f.checked, (long long)f.off_surface, (long long)f.fractional,
      (long long)f.decided, (long long)f.wrong_signs, f.max_error, f.mean_error);
  EXPECT_GT(f.delivered, 1000) << name;
  if (check_max_error) {
    EXPECT_LE(f.max_error, kMaxErrorVoxels) << name << ": max distance error (voxels)";
  }
  EXPECT_LE(f.mean_error, kMeanErrorVoxels) << name << ": mean distance error (voxels)";
  if (c.sign == SignMethod::kUnsigned) return;
  EXPECT_GT(f.decided, f.off_surface / 2) << name << ": too few voxels where the winding number decides";
  EXPECT_LE(double(f.wrong_signs), (1 - kSignAgreement) * double(f.decided))
      << name << ": " << f.wrong_signs << " of " << f.decided << " decided voxels signed against the exact winding "
      << "number";
}

void flip(std::array<uint32_t, 3>& t) { std::swap(t[1], t[2]); }

// `b` appended to `a` (its own vertices).
TriangleMesh joined(TriangleMesh a, const TriangleMesh& b) {
  const uint32_t base = uint32_t(a.vertices.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto t : b.triangles) a.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  return a;
}

Vec3d centroid(const TriangleMesh& m, const std::array<uint32_t, 3>& t) {
  return (m.vertices[t[0]] + m.vertices[t[1]] + m.vertices[t[2]]) * (1.0 / 3);
}

const Vec3d kCentre{0.3, -0.2, 0.1};
TriangleMesh sphere(double radius = 1.0, const Vec3d& centre = kCentre) {
  return makeSphereMesh(centre, radius, 20, 40);
}

// A triangle soup: every triangle with three vertices of its own. validateMesh welds identical positions, so the
// soup and the indexed mesh are the same mesh after validation and give byte-identical fields (the torus: closed,
// so the pseudonormal sign).
TEST(MessyMeshTest, ATriangleSoupGivesTheFieldOfTheIndexedMesh) {
  const TriangleMesh indexed = makeTorusMesh(kCentre, 0.8, 0.3, 48, 16);
  TriangleMesh soup;
  for (const auto& t : indexed.triangles) {
    const uint32_t v = uint32_t(soup.vertices.size());
    for (uint32_t k : t) soup.vertices.push_back(indexed.vertices[k]);
    soup.triangles.push_back({v, v + 1, v + 2});
  }
  const Computed a = compute(indexed), b = compute(soup);
  EXPECT_EQ(b.report.vertices, a.report.vertices);
  EXPECT_TRUE(b.report.closed()) << b.report.summary();
  EXPECT_EQ(b.sign, SignMethod::kPseudonormal);
  EXPECT_EQ(b.mesh.vertices, a.mesh.vertices);
  EXPECT_EQ(b.mesh.triangles, a.mesh.triangles);
  ASSERT_EQ(b.field.size(), a.field.size());
  EXPECT_EQ(std::memcmp(a.field.data(), b.field.data(), a.field.size() * sizeof(float)), 0) << "fields differ";
  expectContract("soup (torus)", b, checkAgainstBruteForce(b));
}

// Duplicated faces (a closed sphere with a band of its faces listed twice, as concatenated STL files give): every
// edge of the band is used by four faces, so the mesh is not closed and auto picks the winding number. That number
// counts the duplicates twice: inside the sphere w = 1 + (the band's solid angle)/4pi, in [1, 2); outside it is
// <= 0 (a convex part's patch is seen from its front). So w > 1/2 is still the sphere's inside — checked here
// against the intact sphere's winding number too — and the distance is unchanged.
TEST(MessyMeshTest, DuplicatedFacesKeepTheSphereSign) {
  const TriangleMesh intact = sphere();
  TriangleMesh doubled = intact;
  int64_t copies = 0;
  for (const auto& t : intact.triangles)
    if (centroid(intact, t).x > kCentre.x + 0.3) doubled.triangles.push_back(t), ++copies;
  ASSERT_GT(copies, 150);
  const Computed c = compute(doubled);
  EXPECT_EQ(c.report.triangles, int64_t(intact.triangles.size()) + copies);
  EXPECT_GT(c.report.non_manifold_edges, 0) << c.report.summary();
  EXPECT_EQ(c.report.boundary_edges, 0) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  expectContract("duplicated faces", c, checkAgainstBruteForce(c));
  expectContract("duplicated faces (vs sphere)", c, checkAgainstBruteForce(c, &intact));
}

// A patch of flipped faces on a closed sphere: validateMesh flips exactly the patch back (the mesh is closed and
// edge-manifold, so its orientation can be made consistent, outward by signed volume); auto then picks the
// pseudonormal sign, and the field is the intact sphere's.
TEST(MessyMeshTest, AFlippedPatchIsRepaired) {
  const TriangleMesh intact = sphere();
  TriangleMesh patched = intact;
  int64_t cap = 0;
  for (auto& t : patched.triangles)
    if (centroid(patched, t).z > kCentre.z + 0.4) flip(t), ++cap;
  ASSERT_GT(cap, 100);
  const Computed c = compute(patched), want = compute(intact);
  EXPECT_EQ(c.report.reoriented_faces, cap) << c.report.summary();
  EXPECT_TRUE(c.report.closed());
  EXPECT_EQ(c.sign, SignMethod::kPseudonormal) << c.reason;
  ASSERT_EQ(c.mesh.triangles.size(), want.mesh.triangles.size());
  for (size_t t = 0; t < c.mesh.triangles.size(); ++t)  // the same corners in the same order
    for (int k = 0; k < 3; ++k)
      ASSERT_EQ(c.mesh.vertices[c.mesh.triangles[t][k]], want.mesh.vertices[want.mesh.triangles[t][k]]) << t;
  EXPECT_EQ(std::memcmp(c.field.data(), want.field.data(), c.field.size() * sizeof(float)), 0) << "fields differ";
  expectContract("flipped patch", c, checkAgainstBruteForce(c));
}

// Two overlapping closed parts (interpenetrating spheres, each closed and outward: a self-intersecting union). The
// pseudonormal test is wrong there — a voxel inside one sphere whose nearest triangle is the other's (outside it) is
// signed outside although w = 1: 1285 of the 15133 decided voxels here — so auto must pick the winding number; the
// union (w >= 1) is inside. The winding sign's one-query-per-brick certificate assumed one sheet per brick and got
// 286 of them wrong near the intersection curve until it learnt to refuse bricks that see two parts. Distances: the
// default stencil fcc12 misses the closest triangle near the concave intersection curve by up to 0.12 voxel at this
// coarse resolution (all voxels; 0.10 on this sample), above the contract's 0.1 (a shortfall docs/algorithm.md
// reports), so the max error is checked on cubic26 here.
TriangleMesh overlappingSpheres() { return joined(sphere(1.0, kCentre), sphere(0.8, kCentre + Vec3d{1.1, 0.3, 0.2})); }

TEST(MessyMeshTest, OverlappingClosedPartsAreSignedByTheWindingNumber) {
  const Computed c = compute(overlappingSpheres());
  EXPECT_TRUE(c.report.closed()) << c.report.summary();
  EXPECT_EQ(c.report.components, 2);
  EXPECT_TRUE(c.report.components_overlap);
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  EXPECT_EQ(c.reason, "auto: the mesh is closed but its parts overlap (2 parts, bounding boxes intersect)");
  expectContract("overlapping parts", c, checkAgainstBruteForce(c), /*check_max_error=*/false);
  const Computed cubic26 = compute(overlappingSpheres(), SignMethod::kAuto, StencilKind::kCubic26);
  expectContract("overlapping parts, cubic26", cubic26, checkAgainstBruteForce(cubic26));
}

// Non-manifold edges: two boxes sharing one edge (four faces at it) and a fin (a quad standing on an edge of the
// first box: three faces at that edge, boundary edges around the fin). Not closed: the winding number; the fin is an
// open sheet outside the boxes, where w stays in (-1/2, 1/2).
TEST(MessyMeshTest, NonManifoldEdgesAreSignedByTheWindingNumber) {
  TriangleMesh m = joined(makeBoxMesh({0, 0, 0}, {1, 1, 1}), makeBoxMesh({1, 1, 0}, {1.8, 1.7, 1}));
  const uint32_t f = uint32_t(m.vertices.size());  // the fin on the edge x = 0, z = 0 (y from 0 to 1)
  m.vertices.push_back({-0.5, 0, -0.4});
  m.vertices.push_back({-0.5, 1, -0.4});
  const uint32_t a = 0, b = 2;  // makeBoxMesh's corners (0, 0, 0) and (0, 1, 0)
  m.triangles.push_back({a, b, f + 1});
  m.triangles.push_back({a, f + 1, f});
  const Computed c = compute(m);
  EXPECT_EQ(c.report.non_manifold_edges, 2) << c.report.summary();
  EXPECT_EQ(c.report.boundary_edges, 3) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  expectContract("non-manifold edges", c, checkAgainstBruteForce(c));
}

// A box whose top face is split into a 4 x 4 grid of quads: the grid's border vertices lie on the side faces' edges
// without being their vertices (T-junctions). Geometrically watertight, topologically open (boundary edges on both
// sides of every T-junction), so auto picks the winding number, which is exactly 1 inside and 0 outside here (so
// every voxel off the surface is decided). `gap` > 0 also pulls the top face back from the +x side: a crack.
TriangleMesh boxWithTJunctions(double gap) {
  const Vec3d lo{-0.7, -0.4, -0.55}, hi{0.8, 0.5, 0.35};
  TriangleMesh box = makeBoxMesh(lo, hi);
  std::erase_if(box.triangles, [&](const auto& t) { return centroid(box, t).z > hi.z - 1e-9; });
  constexpr int n = 4;
  const uint32_t base = uint32_t(box.vertices.size());
  auto lerp = [](double a, double b, int i) { return i == n ? b : a + (b - a) * i / n; };  // exact at the ends
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) box.vertices.push_back({lerp(lo.x, hi.x - gap, i), lerp(lo.y, hi.y, j), hi.z});
  auto at = [&](int i, int j) { return base + uint32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {  // counter-clockwise seen from +z
      box.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      box.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return box;
}

TEST(MessyMeshTest, TJunctionsAreSignedByTheWindingNumber) {
  const Computed c = compute(boxWithTJunctions(0));
  EXPECT_EQ(c.report.boundary_edges, 20) << c.report.summary();  // 16 on the top's border, 4 on the sides' tops
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  const Figures f = checkAgainstBruteForce(c);
  EXPECT_EQ(f.fractional, 0) << "the winding number is 0 or 1 off a watertight surface";
  expectContract("T-junctions", c, f);
}

// The same box with a crack: the top face stops half a voxel short of the +x side. The winding number is no longer
// 0 or 1 near the slit (it leaks through it); where it decides, the sign follows it.
TEST(MessyMeshTest, ACrackIsSignedByTheWindingNumber) {
  const double voxel = gridOf(boxWithTJunctions(0)).voxelSize();
  const Computed c = compute(boxWithTJunctions(0.5 * voxel));
  EXPECT_NEAR(c.grid.voxelSize(), voxel, 1e-9 * voxel);
  EXPECT_EQ(c.report.boundary_edges, 20) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  const Figures f = checkAgainstBruteForce(c);
  EXPECT_GT(f.fractional, 0) << "no voxel sees the crack";
  expectContract("crack", c, f);
}

// Zero-area and needle triangles: half the sphere's edges are split 1e-5 of the way along (both faces at the edge
// split the same way, so the mesh stays closed: each split gives a needle with a 1e-5 angle), and zero-area faces are
// added (a repeated corner; three collinear corners along each split edge). validateMesh drops exactly the zero-area
// faces (`degenerate`) and keeps the needles; the mesh is closed, so the pseudonormal sign.
TEST(MessyMeshTest, ZeroAreaTrianglesAreDroppedAndNeedlesKept) {
  const TriangleMesh base = sphere();
  TriangleMesh m;
  m.vertices = base.vertices;
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> split;  // edge (low id, high id) -> its split vertex
  for (const auto& t : base.triangles) {
    if (centroid(base, t).y <= kCentre.y) continue;
    for (int e = 0; e < 3; ++e) {
      const auto key = std::minmax(t[e], t[(e + 1) % 3]);
      if (split.count(key)) continue;
      const Vec3d &u = base.vertices[key.first], &v = base.vertices[key.second];
      split[key] = uint32_t(m.vertices.size());
      m.vertices.push_back(u + (v - u) * 1e-5);
    }
  }
  // Splits a triangle at the first of its edges that has a split vertex, recursively.
  auto emit = [&](auto&& self, uint32_t a, uint32_t b, uint32_t c) -> void {
    const uint32_t t[3] = {a, b, c};
    for (int e = 0; e < 3; ++e) {
      const auto it = split.find(std::minmax(t[e], t[(e + 1) % 3]));
      if (it == split.end()) continue;
      self(self, t[e], it->second, t[(e + 2) % 3]);
      self(self, it->second, t[(e + 1) % 3], t[(e + 2) % 3]);
      return;
    }
    m.triangles.push_back({a, b, c});
  };
  for (const auto& t : base.triangles) emit(emit, t[0], t[1], t[2]);
  const int64_t kept = int64_t(m.triangles.size());
  int64_t zero_area = 0;
  for (const auto& [edge, mid] : split) m.triangles.push_back({edge.first, mid, edge.second}), ++zero_area;
  for (uint32_t v = 0; v < 10; ++v) m.triangles.push_back({v, v, v + 1}), ++zero_area;
  const Computed c = compute(m);
  EXPECT_EQ(c.report.degenerate, zero_area) << c.report.summary();
  EXPECT_EQ(c.report.triangles, kept);
  EXPECT_TRUE(c.report.closed()) << c.report.summary();
  EXPECT_EQ(c.report.reoriented_faces, 0);
  EXPECT_EQ(c.sign, SignMethod::kPseudonormal) << c.reason;
  expectContract("zero-area and needles", c, checkAgainstBruteForce(c));
}

// Nested shells: a hollow ball (outer sphere outward, inner sphere inward: w = 1 in the shell, 0 in the cavity) and
// a ball in a ball (both outward: w = 2 in the inner one, so inside everywhere within the outer sphere). Both parts
// are consistent, so validateMesh leaves them as they are; their bounding boxes overlap, so auto picks the winding
// number. The pseudonormal test would be right for the hollow ball but not for the ball in a ball (a voxel between
// the spheres whose nearest triangle is the inner one's is in front of it: 2612 of 18220 decided voxels wrong), and
// the winding certificate got 312 wrong there before it refused bricks that see two parts; a bounding box cannot
// tell the two apart.
TEST(MessyMeshTest, NestedShellsFollowTheWindingNumber) {
  TriangleMesh inner = sphere(0.55, kCentre + Vec3d{0.1, 0, -0.05});
  for (const bool hollow : {true, false}) {
    TriangleMesh in = inner;
    if (hollow)
      for (auto& t : in.triangles) flip(t);
    const Computed c = compute(joined(sphere(), in));
    EXPECT_TRUE(c.report.closed()) << c.report.summary();
    EXPECT_EQ(c.report.reoriented_faces, 0);
    EXPECT_TRUE(c.report.components_overlap);
    EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
    const std::string name = hollow ? "nested: hollow ball" : "nested: ball in a ball";
    expectContract(name, c, checkAgainstBruteForce(c));
  }
}

// A single open surface, a flat disk: w lies in (-1/2, 1/2) everywhere off it, so with auto (the winding number: the
// disk has boundary edges) every delivered voxel is outside: the field is >= 0 and equals the unsigned field. Only
// voxels on the disk itself (value 0, where w is undefined) may carry the sign bit (-0).
TEST(MessyMeshTest, AnOpenDiskIsOutsideEverywhere) {
  TriangleMesh disk;
  constexpr int rings = 12, segments = 48;
  disk.vertices.push_back(kCentre);
  for (int i = 1; i <= rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const double r = double(i) / rings, a = 2 * std::numbers::pi * j / segments;
      disk.vertices.push_back(kCentre + Vec3d{r * std::cos(a), r * std::sin(a), 0});
    }
  auto at = [&](int ring, int seg) { return uint32_t(1 + (ring - 1) * segments + seg % segments); };
  for (int j = 0; j < segments; ++j) disk.triangles.push_back({0, at(1, j), at(1, j + 1)});
  for (int i = 1; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      disk.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      disk.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  const Computed c = compute(disk), unsigned_field = compute(disk, SignMethod::kUnsigned);
  EXPECT_EQ(c.report.boundary_edges, segments) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  int64_t negative = 0, different = 0, negative_zero = 0;
  for (size_t i = 0; i < c.field.size(); ++i) {
    const float v = c.field[i], u = unsigned_field.field[i];
    negative += v < 0;
    negative_zero += v == 0 && std::signbit(v);
    different += !(v == u || (std::isnan(v) && std::isnan(u)));
  }
  EXPECT_EQ(negative, 0) << "voxels signed inside an open disk";
  EXPECT_EQ(different, 0) << "the auto field differs from the unsigned one";
  std::printf("[messy] open disk: %lld voxels on the disk are -0\n", (long long)negative_zero);
  expectContract("open disk", c, checkAgainstBruteForce(c));
  expectContract("open disk, unsigned", unsigned_field, checkAgainstBruteForce(unsigned_field));
}

// A cup: a sphere with a large cap removed (one hole, a quarter of the height). Open, so the winding number: inside
// the cup's wall region it is close to 1, and it fades to 0 through the opening.
TEST(MessyMeshTest, ACupIsSignedByTheWindingNumber) {
  TriangleMesh cup = sphere();
  std::erase_if(cup.triangles, [&](const auto& t) { return centroid(cup, t).z > kCentre.z + 0.5; });
  const Computed c = compute(cup);
  EXPECT_GT(c.report.boundary_edges, 0) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  expectContract("cup", c, checkAgainstBruteForce(c));
}

// An open box of big triangles (a cube's two-triangle faces, the top one removed), fine-gridded: its boundary is four
// edges 350 voxels long with vertices only at the corners, so the voxels along the middle of the rim are far from
// every boundary vertex but next to the boundary curve, around which the winding number turns. Bricks there must not
// be signed by their pseudonormals on the strength of one winding query (the certificate's bound on the turn).
// A cube of two-triangle faces around kCentre without its top face.
TriangleMesh openBox() {
  TriangleMesh box = makeBoxMesh(kCentre - Vec3d{1, 1, 1}, kCentre + Vec3d{1, 1, 1});
  std::erase_if(box.triangles, [&](const auto& t) { return centroid(box, t).z > kCentre.z + 0.99; });
  return box;
}

TEST(MessyMeshTest, AnOpenBoxOfBigTrianglesIsSignedByTheWindingNumber) {
  const Computed c = compute(openBox(), SignMethod::kAuto, std::nullopt, 400);
  EXPECT_EQ(c.report.boundary_edges, 4) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  expectContract("open box of big triangles", c, checkAgainstBruteForce(c));
}

// The same box with a band of 16 voxels (the other cases use 3): voxels beyond the rim lie behind the plane of the
// wall whose rim edge is their closest feature, yet on the same side of the sheet as the voxels in front of it (the
// winding number has not jumped there), and the certificates' boxes reach farther from the surface.
TEST(MessyMeshTest, BeyondTheRimOfAnOpenBoxAWideBandIsSignedByTheWindingNumber) {
  const Computed c = compute(openBox(), SignMethod::kAuto, std::nullopt, 160, 16);
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  expectContract("open box, band of 16 voxels", c, checkAgainstBruteForce(c));
}

// A sphere among long thin open triangles (each its own three vertices: all their edges boundary): the boundary
// curves are longer than the winding sign's budget of pieces (MeshSign::maxBoundaryPieces; an upload of stacked
// needles would otherwise make pieces without bound), so no certificate or ball can bound its distance to them and
// every voxel takes a query of its own. The signs are as right as ever.
TEST(MessyMeshTest, BoundaryCurvesPastThePieceBudgetStillGetTheWindingSign) {
  TriangleMesh mesh = sphere(0.5);
  uint64_t seed = 12345;
  auto uniform = [&] {  // deterministic, in [0, 1)
    seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
    return double(seed >> 11) / double(uint64_t(1) << 53);
  };
  constexpr int kNeedles = 450;
  for (int i = 0; i < kNeedles; ++i) {
    const Vec3d a = kCentre + Vec3d{-1.4, 2.8 * uniform() - 1.4, 2.8 * uniform() - 1.4};
    const Vec3d b = a + Vec3d{2.8, 0.3 * uniform(), 0.3 * uniform()};
    const Vec3d c = b + Vec3d{0, 0.02, 0.02};
    const auto v = uint32_t(mesh.vertices.size());
    mesh.vertices.insert(mesh.vertices.end(), {a, b, c});
    mesh.triangles.push_back({v, v + 1, v + 2});
  }
  const int resolution = 96;
  const Computed c = compute(mesh, SignMethod::kAuto, std::nullopt, resolution);
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  // The pieces the boundary would take (16 voxels each at most), past the budget.
  double pieces = 0;
  for (int i = 0; i < kNeedles; ++i) {
    const auto& t = c.mesh.triangles[c.mesh.triangles.size() - 1 - size_t(i)];
    for (int e = 0; e < 3; ++e)
      pieces += std::max(
          1.0, std::ceil((c.mesh.vertices[t[(e + 1) % 3]] - c.mesh.vertices[t[e]]).length() / c.grid.voxelSize() / 16));
  }
  EXPECT_GT(pieces, double(MeshSign::maxBoundaryPieces(c.mesh.triangles.size())));
  expectContract("needles past the piece budget", c, checkAgainstBruteForce(c));
}

// The pseudonormal of an edge with three or more uses (here: the top face of a cube listed twice) is kept apart from
// the manifold edges' (computed from the one other triangle): beyond such an edge, outside both faces' planes' wedge,
// the point is outside through every triangle that has the edge. The same points without the duplicate: the manifold
// path. (The exact answer: outside the unit cube.)
TEST(MessyMeshTest, EdgesOfThreeUsesKeepAPseudonormalThatSumsEveryFace) {
  std::vector<Vec3d> vertices;
  for (int i = 0; i < 8; ++i) vertices.push_back({double(i & 1), double((i >> 1) & 1), double((i >> 2) & 1)});
  std::vector<std::array<uint32_t, 3>> triangles = {
      {0, 2, 3}, {0, 3, 1}, {0, 1, 5}, {0, 5, 4}, {0, 4, 6}, {0, 6, 2},  // z = 0, y = 0, x = 0
      {1, 3, 7}, {1, 7, 5}, {2, 6, 7}, {2, 7, 3}, {4, 5, 7}, {4, 7, 6},  // x = 1, y = 1, z = 1
  };
  for (int duplicated = 0; duplicated < 2; ++duplicated) {
    if (duplicated) triangles.push_back(triangles[11]);
    std::unique_ptr<MeshSign> sign;
    ASSERT_TRUE(IsOk(MeshSign::build(std::make_shared<const std::vector<Vec3d>>(vertices),
                                     std::make_shared<const std::vector<std::array<uint32_t, 3>>>(triangles),
                                     SignMethod::kPseudonormal, nullptr, &sign)));
    int checked = 0;
    for (double along : {0.1, 0.5, 0.9})
      for (double a : {0.05, 0.2, 0.6})
        for (double b : {0.05, 0.2, 0.6}) {
          // Beyond the edge y = 1, z = 1 (triangles 8, 11 and the copy) and beyond the edge x = 0, z = 1 (4, 11).
          const Vec3d p1{along, 1 + a, 1 + b}, p2{-a, along, 1 + b};
          for (uint32_t t : {8u, 11u, 12u}) {
            if (t == 12u && !duplicated) continue;
            EXPECT_FALSE(sign->inside(p1, t, std::hypot(a, b))) << "t " << t << " duplicated " << duplicated;
            ++checked;
          }
          for (uint32_t t : {4u, 11u, 12u}) {
            if (t == 12u && !duplicated) continue;
            EXPECT_FALSE(sign->inside(p2, t, std::hypot(a, b))) << "t " << t << " duplicated " << duplicated;
            ++checked;
          }
        }
    EXPECT_EQ(checked, duplicated ? 162 : 108);
  }
}

// A flipped patch on a closed part of a mesh that is open elsewhere (a sphere with its cap flipped, and beside it an
// open square of its own): the closed part is re-oriented as if it were the whole mesh — the repair is per part — and
// the sign is the repaired mesh's winding number. Until 2026-11-29 only a wholly closed mesh was repaired: the open
// square kept the sphere's flipped cap, whose voxels took the flipped sign (2904 of 20342 decided voxels wrong).
TEST(MessyMeshTest, AFlippedPatchOnAClosedPartIsRepairedBesideAnOpenPart) {
  TriangleMesh disk;  // a flat square of two triangles beside the sphere, its own vertices
  const Vec3d o = kCentre + Vec3d{1.4, -0.5, -0.5};
  disk.vertices = {o, o + Vec3d{0.6, 0, 0}, o + Vec3d{0.6, 1.0, 0}, o + Vec3d{0, 1.0, 0}};
  disk.triangles = {{0, 1, 2}, {0, 2, 3}};
  const TriangleMesh intact = joined(sphere(), disk);
  TriangleMesh patched = intact;
  int64_t cap = 0;
  const size_t sphere_faces = sphere().triangles.size();
  for (size_t t = 0; t < sphere_faces; ++t)
    if (centroid(patched, patched.triangles[t]).z > kCentre.z + 0.4) flip(patched.triangles[t]), ++cap;
  ASSERT_GT(cap, 100);
  const Computed c = compute(patched);
  EXPECT_EQ(c.report.reoriented_faces, cap) << c.report.summary();
  EXPECT_EQ(c.report.boundary_edges, 4) << c.report.summary();
  EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
  TriangleMesh want = intact;
  ASSERT_TRUE(IsOk(validateMesh(&want, nullptr)));
  // fcc12 misses the closest triangle by up to 0.11 voxel near the square's rim at this coarse resolution (the
  // shortfall of the overlapping spheres, docs/algorithm.md): the max error is checked on cubic26.
  expectContract("flipped patch beside an open part", c, checkAgainstBruteForce(c, &want), /*check_max_error=*/false);
  const Computed cubic26 = compute(patched, SignMethod::kAuto, StencilKind::kCubic26);
  expectContract("flipped patch beside an open part, cubic26", cubic26, checkAgainstBruteForce(cubic26, &want));
}

// Double-sided sheets: every face also listed the other way round (coincident faces of opposite orientation, as
// exporters write two-sided cards and foliage). Their solid angles cancel: w = 0 everywhere off them, so every
// voxel is outside. A single double-sided triangle counts as closed (each edge has its two faces, one each way),
// yet no pseudonormal can be right about it: auto must take the winding number. A double-sided disk has
// non-manifold edges (four faces at each inner edge). Until 2026-11-29 the winding sign's one-query-per-brick
// certificate took each voxel's closest face (one of the two) for the only sheet there and signed the voxels
// behind it inside (270 of 861 for the triangle), and auto signed the triangle by its pseudonormals.
TEST(MessyMeshTest, DoubleSidedSheetsAreOutsideOnBothSides) {
  TriangleMesh triangle;
  triangle.vertices = {kCentre, kCentre + Vec3d{1.6, 0.2, 0.3}, kCentre + Vec3d{0.3, 1.4, -0.4}};
  triangle.triangles = {{0, 1, 2}, {0, 2, 1}};
  TriangleMesh disk;
  constexpr int segments = 24;
  disk.vertices.push_back(kCentre);
  for (int j = 0; j < segments; ++j) {
    const double a = 2 * std::numbers::pi * j / segments;
    disk.vertices.push_back(kCentre + Vec3d{std::cos(a), std::sin(a), 0.3 * std::cos(a)});
  }
  for (uint32_t j = 0; j < segments; ++j) {
    const uint32_t a = 1 + j, b = 1 + (j + 1) % segments;
    disk.triangles.push_back({0, a, b});
    disk.triangles.push_back({0, b, a});
  }
  for (const bool is_disk : {false, true}) {
    const std::string name = is_disk ? "double-sided disk" : "double-sided triangle";
    const Computed c = compute(is_disk ? disk : triangle);
    EXPECT_EQ(c.sign, SignMethod::kWinding) << name << ": " << c.reason;
    int64_t negative = 0;
    for (float v : c.field) negative += v < 0;
    EXPECT_EQ(negative, 0) << name << ": voxels signed inside a sheet of zero volume";
    expectContract(name, c, checkAgainstBruteForce(c));
  }
}

// A closed part oriented inward that crosses an outward one (a sphere, and a smaller one listed inward that pokes
// out of it): w = 1 in the outer sphere only, 0 where both hold a point (the inward one cancels it), -1 in the
// inward sphere's part outside the other; inside is w > 1/2. The winding sign's brick certificate compared only the
// parts of the voxels' closest triangles, so a brick near the crossing whose voxels were all nearest one sphere, cut
// by the other's sheet, was signed by one sphere's pseudonormal: w = 0 voxels inside.
TEST(MessyMeshTest, AnInwardPartCrossingAnOutwardOneFollowsTheWindingNumber) {
  TriangleMesh inward = sphere(0.8, kCentre + Vec3d{1.1, 0.3, 0.2});
  for (auto& t : inward.triangles) flip(t);
  // Two tetrahedra: the unit one outward, a larger one inward through it (a review's random case).
  TriangleMesh tetrahedra;
  const Vec3d lo{-0.3391331775038804, 0.05509638044825094, -0.39742324912391613};
  const double side = 1.4526763980543636;
  tetrahedra.vertices = {{0, 0, 0},
                         {1, 0, 0},
                         {0, 1, 0},
                         {0, 0, 1},
                         lo,
                         lo + Vec3d{side, 0, 0},
                         lo + Vec3d{0, side, 0},
                         lo + Vec3d{0, 0, side}};
  tetrahedra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {4, 5, 6}, {4, 7, 5}, {4, 6, 7}, {5, 7, 6}};
  struct Case {
    std::string name;
    TriangleMesh mesh;
    int resolution, padding;
  };
  // The tetrahedra on `distband compute --resolution 24 / 32 --limit-voxels 3`'s grids (padding 3): 7 and 91 wrong.
  const Case cases[] = {{"inward sphere crossing", joined(sphere(), inward), kResolution, kPadding},
                        {"inward sphere crossing", joined(sphere(), inward), 90, kPadding},
                        {"inward tetrahedron crossing", tetrahedra, 24, 3},
                        {"inward tetrahedron crossing", tetrahedra, 32, 3}};
  for (const Case& k : cases) {
    const Computed c = compute(k.mesh, SignMethod::kAuto, std::nullopt, k.resolution, kLimitVoxels, k.padding);
    EXPECT_EQ(c.report.reoriented_faces, 0);  // each part is consistent: kept as it is
    EXPECT_EQ(c.sign, SignMethod::kWinding) << c.reason;
    expectContract(k.name + " at " + std::to_string(k.resolution), c, checkAgainstBruteForce(c),
                   /*check_max_error=*/false);
  }
}

}  // namespace
}  // namespace distband
