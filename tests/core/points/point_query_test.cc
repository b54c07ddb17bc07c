// Tests for core/points (the point queries): distances, closest points, ids and gradients against brute force
// (tests/support/brute_mesh, which shares no code with core/), signs against the exact winding number and against the
// grid path's own signs at voxel centres, point seeds and seed volumes against brute force, the limit, errors and
// interruption.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/field/compute_field.h"
#include "core/field/field_plan.h"
#include "core/io/dense_field.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/point_plan.h"
#include "core/points/point_query.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

using testing::bruteDistance;
using testing::bruteWinding;

TriangleMesh load(const std::string& name, MeshReport* report = nullptr) {
  TriangleMesh mesh;
  EXPECT_TRUE(IsOk(loadMesh(std::string(DISTBAND_TEST_DATA_DIR "/meshes/") + name, &mesh, report)));
  return mesh;
}

struct Box {
  Vec3d lo, hi;
  double diagonal() const { return (hi - lo).length(); }
};

Box boundsOf(const std::vector<Vec3d>& v) {
  Box b{v[0], v[0]};
  for (const Vec3d& p : v) {
    b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
    b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
  }
  return b;
}

/// `n` points uniform in the box grown by `grow` of its diagonal, and `n` Gaussian around mesh vertices (sigma = 1 %
/// of the diagonal): the two distributions of the acceptance bench, at test size.
std::vector<Vec3d> samplePoints(const TriangleMesh& mesh, int n, uint32_t seed, double grow = 0.1) {
  const Box b = boundsOf(mesh.vertices);
  const double g = grow * b.diagonal(), sigma = 0.01 * b.diagonal();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(b.lo.x - g, b.hi.x + g), uy(b.lo.y - g, b.hi.y + g),
      uz(b.lo.z - g, b.hi.z + g);
  std::normal_distribution<double> noise(0, sigma);
  std::uniform_int_distribution<size_t> vertex(0, mesh.vertices.size() - 1);
  std::vector<Vec3d> points;
  for (int i = 0; i < n; ++i) points.push_back({ux(rng), uy(rng), uz(rng)});
  for (int i = 0; i < n; ++i) {
    const Vec3d v = mesh.vertices[vertex(rng)];
    points.push_back({v.x + noise(rng), v.y + noise(rng), v.z + noise(rng)});
  }
  return points;
}

struct Outputs {
  std::vector<double> distance;
  std::vector<Vec3d> closest;
  std::vector<int64_t> feature;
  std::vector<Vec3d> gradient;
};

Status run(const PointSearch& search, const std::vector<Vec3d>& at, double limit, Outputs* o,
           const Interrupter* interrupter = nullptr) {
  o->distance.assign(at.size(), 0);
  o->closest.assign(at.size(), {});
  o->feature.assign(at.size(), 0);
  o->gradient.assign(at.size(), {});
  PointQueryOptions options;
  options.limit = limit;
  options.interrupter = interrupter;
  return queryPoints(search, at.data(), at.size(), options,
                     {o->distance.data(), o->closest.data(), o->feature.data(), o->gradient.data()});
}

PointSearch meshSearch(const TriangleMesh& mesh, const MeshReport& report, std::optional<SignMethod> sign,
                       double limit = std::numeric_limits<double>::infinity(), PointPlan* plan_out = nullptr) {
  FieldRequest r;
  r.seeds = SeedKind::kMesh;
  r.mesh_sign = sign;
  r.limit_world = limit;
  PointPlan plan;
  EXPECT_TRUE(IsOk(planPoints(r, &report, nullptr, &plan)));
  PointSeedSource source;
  source.mesh = &mesh;
  PointSearch search;
  EXPECT_TRUE(IsOk(completePointSearch(plan, source, nullptr, &search)));
  if (plan_out) *plan_out = plan;
  return search;
}

double triangleDistance(const TriangleMesh& mesh, int64_t t, const Vec3d& p) {
  TriangleMesh one;
  for (uint32_t v : mesh.triangles[size_t(t)]) one.vertices.push_back(mesh.vertices[v]);
  one.triangles.push_back({0, 1, 2});
  return bruteDistance(one, p);
}

/// Distances, closest points, ids and gradients on a mesh against brute force; signs against the exact winding
/// number wherever it is clearly inside or outside.
void checkMesh(const std::string& name, std::optional<SignMethod> sign, SignMethod expected_method, int n) {
  SCOPED_TRACE(name);
  MeshReport report;
  const TriangleMesh mesh = load(name, &report);
  PointPlan plan;
  const PointSearch search = meshSearch(mesh, report, sign, std::numeric_limits<double>::infinity(), &plan);
  EXPECT_EQ(plan.mesh_sign, expected_method);
  const std::vector<Vec3d> at = samplePoints(mesh, n, 11);
  Outputs o;
  ASSERT_TRUE(IsOk(run(search, at, std::numeric_limits<double>::infinity(), &o)));
  const double tolerance = 1e-9 * boundsOf(mesh.vertices).diagonal();
  int sign_checked = 0, sign_wrong = 0;
  for (size_t i = 0; i < at.size(); ++i) {
    const Vec3d& p = at[i];
    const double exact = bruteDistance(mesh, p);
    const double d = std::abs(o.distance[i]);
    ASSERT_NEAR(d, exact, tolerance) << "point " << i;
    // The closest point lies on the named triangle at the distance reported.
    EXPECT_NEAR((p - o.closest[i]).length(), d, tolerance) << "point " << i;
    EXPECT_NEAR(triangleDistance(mesh, o.feature[i], p), exact, tolerance) << "point " << i;
    EXPECT_NEAR(triangleDistance(mesh, o.feature[i], o.closest[i]), 0, tolerance) << "point " << i;
    // The gradient: a unit vector along (p - closest), oriented by the sign.
    const Vec3d g = o.gradient[i];
    EXPECT_NEAR(g.length(), 1.0, 1e-9) << "point " << i;
    if (d > tolerance) {
      const Vec3d along = (p - o.closest[i]) * ((o.distance[i] < 0 ? -1.0 : 1.0) / d);
      EXPECT_NEAR((g - along).length(), 0, 1e-6) << "point " << i;
    }
    const double w = bruteWinding(mesh, p);
    if (std::abs(w - 0.5) > 0.05 && d > tolerance) {
      ++sign_checked;
      sign_wrong += (o.distance[i] < 0) != (w > 0.5);
    }
  }
  EXPECT_GT(sign_checked, n);
  EXPECT_EQ(sign_wrong, 0) << "of " << sign_checked;
}

TEST(PointQueryTest, ClosedMeshesAreExactAndSignedByPseudonormals) {
  checkMesh("bunny.obj", std::nullopt, SignMethod::kPseudonormal, 1000);
  checkMesh("fandisk.off", std::nullopt, SignMethod::kPseudonormal, 400);
}

TEST(PointQueryTest, OpenMeshesAreSignedByTheWindingNumber) {
  checkMesh("teapot.obj", std::nullopt, SignMethod::kWinding, 1500);
}

// Ray parity is the winding number's parity only on a closed mesh (on an open one it differs near the holes).
TEST(PointQueryTest, ParitySignsAClosedMesh) { checkMesh("bunny.obj", SignMethod::kParity, SignMethod::kParity, 300); }

TEST(PointQueryTest, AnalyticShapesAgreeWithTheirSdf) {
  const Vec3d lo{-1, -2, -0.5}, hi{2, 1, 0.75};
  TriangleMesh box = testing::makeBoxMesh(lo, hi);
  MeshReport report;
  ASSERT_TRUE(IsOk(validateMesh(&box, &report)));
  const PointSearch search = meshSearch(box, report, SignMethod::kPseudonormal);
  const std::vector<Vec3d> at = samplePoints(box, 2000, 5, 0.5);
  Outputs o;
  ASSERT_TRUE(IsOk(run(search, at, std::numeric_limits<double>::infinity(), &o)));
  for (size_t i = 0; i < at.size(); ++i)
    ASSERT_NEAR(o.distance[i], testing::boxSdf(lo, hi, at[i]), 1e-12) << "point " << i;
}

TEST(PointQueryTest, SignsEqualTheGridPathsAtVoxelCentres) {
  for (const auto& [name, method] : {std::pair<std::string, SignMethod>{"bunny.obj", SignMethod::kPseudonormal},
                                     {"teapot.obj", SignMethod::kWinding},
                                     {"bunny.obj", SignMethod::kParity}}) {
    SCOPED_TRACE(name + " " + std::string(signMethodName(method)));
    MeshReport report;
    const TriangleMesh mesh = load(name, &report);
    FieldRequest request;
    request.seeds = SeedKind::kMesh;
    request.mesh_sign = method;
    MeshGridOptions go;
    go.resolution = 40;
    Grid grid;
    GridPadding padding;
    ASSERT_TRUE(IsOk(gridForMesh(mesh, go, request.limit(), &grid, &padding)));
    FieldPlan plan;
    ASSERT_TRUE(IsOk(planField(request, grid, &report, &plan)));
    SeedSource source;
    source.mesh = &mesh;
    FieldInputs inputs;
    ASSERT_TRUE(IsOk(buildFieldInputs(plan, grid, nullptr, source, nullptr, &inputs)));
    DenseField field(grid, std::numeric_limits<float>::quiet_NaN());
    computeField(plan, grid, std::move(inputs), plan.runOptions(), [&](SegmentBricks&& s) { field.add(s); });

    const PointSearch search = meshSearch(mesh, report, method);
    std::vector<Vec3d> centres;
    const Coord d = grid.dims();
    for (int z = 0; z < d.z; ++z)
      for (int y = 0; y < d.y; ++y)
        for (int x = 0; x < d.x; ++x) centres.push_back(grid.worldOf({x, y, z}));
    Outputs o;
    ASSERT_TRUE(IsOk(run(search, centres, std::numeric_limits<double>::infinity(), &o)));
    int64_t compared = 0, differ = 0;
    for (size_t i = 0; i < centres.size(); ++i) {
      const float g = field.values()[i];
      ASSERT_FALSE(std::isnan(g)) << "voxel " << i;
      if (std::abs(o.distance[i]) < 1e-6 * grid.voxelSize()) continue;  // on the surface: either sign
      // The grid's winding sign reuses a voxel's sign within its distance less a voxel; near an open mesh's holes
      // the winding number itself is close to 1/2 and either answer is right.
      if (method == SignMethod::kWinding && std::abs(bruteWinding(mesh, centres[i]) - 0.5) < 0.05) continue;
      ++compared;
      differ += (g < 0) != (o.distance[i] < 0);
    }
    EXPECT_GT(compared, centres.size() / 2);
    EXPECT_EQ(differ, 0) << "of " << compared;
  }
}

TEST(PointQueryTest, PointsBeyondTheLimitGetTheLimitWithTheirSign) {
  MeshReport report;
  const TriangleMesh mesh = load("bunny.obj", &report);
  const double limit = 0.02 * boundsOf(mesh.vertices).diagonal();
  for (SignMethod method : {SignMethod::kPseudonormal, SignMethod::kWinding, SignMethod::kUnsigned}) {
    SCOPED_TRACE(signMethodName(method));
    const PointSearch search = meshSearch(mesh, report, method, limit);
    const std::vector<Vec3d> at = samplePoints(mesh, 600, 3);
    Outputs o;
    ASSERT_TRUE(IsOk(run(search, at, limit, &o)));
    int beyond = 0;
    for (size_t i = 0; i < at.size(); ++i) {
      const double exact = bruteDistance(mesh, at[i]);
      const bool inside = method != SignMethod::kUnsigned && bruteWinding(mesh, at[i]) > 0.5;
      if (exact > limit * (1 + 1e-9)) {
        ++beyond;
        EXPECT_EQ(o.distance[i], inside ? -limit : limit) << "point " << i;
        EXPECT_EQ(o.feature[i], -1);
        EXPECT_TRUE(std::isnan(o.closest[i].x));
        EXPECT_EQ(o.gradient[i].length(), 0);
      } else if (exact < limit * (1 - 1e-9)) {
        EXPECT_NEAR(std::abs(o.distance[i]), exact, 1e-9);
        EXPECT_GE(o.feature[i], 0);
      }
    }
    EXPECT_GT(beyond, 100);
  }
}

TEST(PointQueryTest, PointSeedsAreExact) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-5, 5);
  std::vector<Vec3d> seeds, at;
  for (int i = 0; i < 500; ++i) seeds.push_back({u(rng), u(rng), u(rng)});
  seeds.push_back(seeds[7]);  // a duplicate: the lower index wins
  for (int i = 0; i < 3000; ++i) at.push_back({2 * u(rng), 2 * u(rng), 2 * u(rng)});
  at.push_back(seeds[7]);
  FieldRequest r;
  r.seeds = SeedKind::kPoints;
  PointPlan plan;
  ASSERT_TRUE(IsOk(planPoints(r, nullptr, nullptr, &plan)));
  PointSeedSource source;
  source.points = &seeds;
  PointSearch search;
  ASSERT_TRUE(IsOk(completePointSearch(plan, source, nullptr, &search)));
  Outputs o;
  ASSERT_TRUE(IsOk(run(search, at, std::numeric_limits<double>::infinity(), &o)));
  for (size_t i = 0; i < at.size(); ++i) {
    double best = std::numeric_limits<double>::infinity();
    int64_t best_id = -1;
    for (size_t s = 0; s < seeds.size(); ++s) {
      const double d2 = (at[i] - seeds[s]).lengthSqr();
      if (d2 < best) best = d2, best_id = int64_t(s);
    }
    ASSERT_EQ(o.distance[i], std::sqrt(best)) << "point " << i;
    ASSERT_EQ(o.feature[i], best_id) << "point " << i;
    ASSERT_EQ(o.closest[i], seeds[size_t(best_id)]);
  }
  EXPECT_EQ(o.feature.back(), 7);
  EXPECT_EQ(o.gradient.back().length(), 0);  // on a seed: no direction
}

// Seeds in one place leave the tree nothing to split by: it still holds them all, and ties go to the lowest index.
TEST(PointQueryTest, CoincidentSeedsAreAllFound) {
  std::vector<Vec3d> seeds(5000, Vec3d{1, 2, 3});
  seeds.push_back({1, 2, 2});
  std::vector<Vec3d> at(2000, Vec3d{1, 2, 4});
  at.push_back({1, 2, 1});
  PointSet set;
  ASSERT_TRUE(IsOk(PointSet::build(seeds, {}, nullptr, &set)));
  PointSearch search;
  search.seeds = SeedKind::kPoints;
  search.points = std::make_shared<PointSet>(std::move(set));
  Outputs o;
  ASSERT_TRUE(IsOk(run(search, at, std::numeric_limits<double>::infinity(), &o)));
  for (size_t i = 0; i + 1 < at.size(); ++i) ASSERT_EQ(o.feature[i], 0);
  EXPECT_EQ(o.feature.back(), 5000);
  EXPECT_EQ(o.distance.back(), 1);
}

TEST(PointQueryTest, SeedVolumesAreExactInsideAndOutsideTheirGrid) {
  const Coord dims{11, 9, 7};
  const Grid lattice({0.5, -1, 2}, 0.25, dims);
  auto mask = std::make_shared<std::vector<uint8_t>>(size_t(lattice.voxelCount()), 0);
  std::mt19937 rng(4);
  for (auto& m : *mask) m = rng() % 5 == 0;
  std::uniform_real_distribution<double> ux(-1, 4), uy(-2.5, 2), uz(1, 5);
  std::vector<Vec3d> at;
  for (int i = 0; i < 3000; ++i) at.push_back({ux(rng), uy(rng), uz(rng)});
  for (int z = 0; z < dims.z; ++z)
    for (int y = 0; y < dims.y; ++y)
      for (int x = 0; x < dims.x; ++x) at.push_back(lattice.worldOf({x, y, z}));
  for (bool signed_field : {false, true}) {
    SCOPED_TRACE(signed_field ? "mask-inside" : "unsigned");
    FieldRequest r;
    r.seeds = SeedKind::kVolume;
    r.inside_negative = signed_field;
    PointPlan plan;
    ASSERT_TRUE(IsOk(planPoints(r, nullptr, &lattice, &plan)));
    PointSeedSource source;
    source.mask = mask;
    source.lattice = lattice;
    PointSearch search;
    ASSERT_TRUE(IsOk(completePointSearch(plan, source, nullptr, &search)));
    Outputs o;
    ASSERT_TRUE(IsOk(run(search, at, std::numeric_limits<double>::infinity(), &o)));
    for (size_t i = 0; i < at.size(); ++i) {
      const Vec3d q = lattice.indexOf(at[i]);
      const Coord cell{int(std::round(q.x)), int(std::round(q.y)), int(std::round(q.z))};
      const bool in = lattice.contains(cell) && (*mask)[size_t(lattice.denseIndex(cell))];
      const bool negative = signed_field && in;
      double best = std::numeric_limits<double>::infinity();
      for (int64_t v = 0; v < lattice.voxelCount(); ++v)
        if (bool((*mask)[size_t(v)]) != negative) {
          const Coord c{int(v % dims.x), int(v / dims.x % dims.y), int(v / (dims.x * dims.y))};
          best = std::min(best, (at[i] - lattice.worldOf(c)).length());
        }
      ASSERT_NEAR(o.distance[i], negative ? -best : best, 1e-12) << "point " << i;
      ASSERT_NEAR((at[i] - o.closest[i]).length(), best, 1e-12);
      ASSERT_EQ(bool((*mask)[size_t(o.feature[i])]), !negative);
    }
  }
}

TEST(PointQueryTest, RefusesNonFinitePointsByIndexAndStopsWhenInterrupted) {
  MeshReport report;
  const TriangleMesh mesh = load("bunny.obj", &report);
  const PointSearch search = meshSearch(mesh, report, std::nullopt);
  std::vector<Vec3d> at = samplePoints(mesh, 1000, 2);
  at[1234].y = std::numeric_limits<double>::quiet_NaN();
  Outputs o;
  EXPECT_TRUE(IsError(run(search, at, std::numeric_limits<double>::infinity(), &o), Status::Code::kInvalidArgument,
                      "point 1234"));
  at[1234].y = 0;
  Interrupter stop;
  stop.cancel(Status::Code::kCancelled, "test stop");
  EXPECT_TRUE(IsError(run(search, at, std::numeric_limits<double>::infinity(), &o, &stop), Status::Code::kCancelled,
                      "test stop"));
}

TEST(PointQueryTest, PlansRefuseWhatAPointQueryDoesNotTake) {
  FieldRequest r;
  r.seeds = SeedKind::kPoints;
  r.inside_negative = true;
  PointPlan plan;
  EXPECT_TRUE(IsError(planPoints(r, nullptr, nullptr, &plan), Status::Code::kInvalidArgument, "sign"));
  r = {};
  r.seeds = SeedKind::kMesh;
  r.stencil = StencilKind::kFcc12;
  MeshReport report;
  EXPECT_TRUE(IsError(planPoints(r, &report, nullptr, &plan), Status::Code::kInvalidArgument, "stencil"));
  r = {};
  r.seeds = SeedKind::kMesh;
  r.limit_voxels = 3;
  EXPECT_TRUE(IsError(planPoints(r, &report, nullptr, &plan), Status::Code::kInvalidArgument, "limit_voxels"));
}

}  // namespace
}  // namespace distband
