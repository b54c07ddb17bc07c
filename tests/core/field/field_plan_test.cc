// Tests for the defaults core decides once: the padding that holds the limit (core/mesh/mesh_grid), the
// sign method auto (core/seeds/mesh_seeds), and the closest-feature ids the engine reports, each checked against
// exact references (brute-force distances and winding numbers from tests/support, which share no code with core/).
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/band/band_engine.h"
#include "core/field/field_plan.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_mesh.h"

namespace distband {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TriangleMesh unitBox() { return testing::makeBoxMesh({0, 0, 0}, {1, 1, 1}); }

// The band reaches `limit` beyond the bounds: padding * h >= limit, in whichever unit the limit came.
TEST(FieldDefaultsTest, DefaultPaddingHoldsTheLimit) {
  const TriangleMesh box = unitBox();
  struct Case {
    double voxel_size;
    int resolution;
    double limit_world, limit_voxels;
    int expect_padding;  // -1: only check padding * h >= limit
  };
  const Case cases[] = {
      {0.1, 0, kInf, 0, kDefaultPaddingVoxels},  // no limit: the default margin
      {0.1, 0, 0.2, 0, kDefaultPaddingVoxels},   // a limit inside the default margin
      {0.1, 0, 0.55, 0, 6},                      // 5.5 voxels -> 6
      {0.1, 0, kInf, 5, 5},                      // in voxels, exact: not rounded up
      {0, 256, 0.2, 0, 37},                      // resolution: h depends on the padding
      {0, 128, 0, 20, 20},
  };
  for (const Case& c : cases) {
    MeshGridOptions o;
    o.voxel_size = c.voxel_size;
    o.resolution = c.resolution;
    Grid g;
    GridPadding p;
    ASSERT_TRUE(IsOk(gridForMesh(box, o, {c.limit_world, c.limit_voxels}, &g, &p)));
    if (c.expect_padding >= 0) {
      EXPECT_EQ(p.voxels, c.expect_padding) << c.voxel_size << " " << c.limit_world;
    }
    const double limit_voxels = c.limit_voxels > 0 ? c.limit_voxels : c.limit_world / g.voxelSize();
    if (std::isfinite(limit_voxels)) {
      EXPECT_GE(p.voxels, limit_voxels - 1e-9);
    }
    EXPECT_FALSE(p.band_clipped);
    if (c.resolution > 0) {
      EXPECT_EQ(std::max({g.dims().x, g.dims().y, g.dims().z}), c.resolution);
    }
    EXPECT_NEAR(g.origin().x, -p.voxels * g.voxelSize(), 1e-12);
  }
}

TEST(FieldDefaultsTest, ExplicitOrCappedPaddingReportsAClippedBand) {
  const TriangleMesh box = unitBox();
  MeshGridOptions o;
  o.voxel_size = 0.1;
  o.padding_voxels = 2;  // explicit wins, but clips a 5-voxel band
  Grid g;
  GridPadding p;
  ASSERT_TRUE(IsOk(gridForMesh(box, o, {0.5, 0}, &g, &p)));
  EXPECT_EQ(p.voxels, 2);
  EXPECT_TRUE(p.band_clipped);
  // A limit far larger than the object at a fixed resolution: the object keeps half the voxels, the band is clipped.
  MeshGridOptions r;
  r.resolution = 65;
  ASSERT_TRUE(IsOk(gridForMesh(box, r, {100, 0}, &g, &p)));
  EXPECT_EQ(p.voxels, 16);
  EXPECT_TRUE(p.band_clipped);
  EXPECT_NEAR(g.voxelSize(), 1.0 / 32, 1e-12);
  // An explicit box is the region asked for: no margin by default, nothing reported clipped.
  MeshGridOptions b;
  b.voxel_size = 0.1;
  b.box_min = Vec3d{0, 0, 0};
  b.box_max = Vec3d{1, 1, 1};
  ASSERT_TRUE(IsOk(gridForMesh(box, b, {0.5, 0}, &g, &p)));
  EXPECT_EQ(p.voxels, 0);
  EXPECT_FALSE(p.band_clipped);
}

// The planner makes every choice left open, the same way for every caller.
TEST(FieldDefaultsTest, PlannerDecidesModeSitesStencilSignAndLimit) {
  const Grid grid({0, 0, 0}, 0.25, {32, 32, 32});
  MeshReport closed, open;
  open.boundary_edges = 4;
  FieldPlan p;
  FieldRequest mesh;
  mesh.seeds = SeedKind::kMesh;
  mesh.limit_voxels = 6;
  ASSERT_TRUE(IsOk(planField(mesh, grid, &closed, &p)));
  EXPECT_EQ(p.mode, PropagationMode::kExact);
  EXPECT_EQ(p.sites, SiteKind::kTriangle);
  EXPECT_EQ(p.stencil, StencilKind::kFcc12);
  EXPECT_EQ(p.mesh_sign, SignMethod::kPseudonormal);
  EXPECT_TRUE(p.signedField());
  EXPECT_DOUBLE_EQ(p.limit_world, 1.5);  // 6 voxels of 0.25: the limit is kept once, in world units
  EXPECT_DOUBLE_EQ(p.meshSeedOptions(grid).limit_voxels, 6);
  EXPECT_DOUBLE_EQ(p.runOptions().limit_world, 1.5);
  EXPECT_DOUBLE_EQ(p.bandOptions(p.runOptions()).limit_world, 1.5);
  EXPECT_EQ(p.bandOptions(p.runOptions()).stencil, StencilKind::kFcc12);
  ASSERT_TRUE(IsOk(planField(mesh, grid, &open, &p)));
  EXPECT_EQ(p.mesh_sign, SignMethod::kWinding);
  EXPECT_EQ(p.signName(), "winding");
  mesh.mode = PropagationMode::kPaper;
  mesh.mesh_sign = SignMethod::kUnsigned;
  ASSERT_TRUE(IsOk(planField(mesh, grid, &closed, &p)));
  EXPECT_EQ(p.sites, SiteKind::kPoint);
  EXPECT_EQ(p.stencil, StencilKind::kCubic26);
  EXPECT_EQ(p.meshSeedOptions(grid).mode, MeshSiteMode::kPaper);
  EXPECT_FALSE(p.signedField());
  EXPECT_EQ(p.sign_reason, "requested");

  FieldRequest volume;
  volume.seeds = SeedKind::kVolume;
  volume.limit_world = 2;
  volume.stencil = StencilKind::kCubic6;
  ASSERT_TRUE(IsOk(planField(volume, grid, nullptr, &p)));
  EXPECT_EQ(p.stencil, StencilKind::kCubic6);
  EXPECT_FALSE(p.signedField());
  volume.inside_negative = true;
  ASSERT_TRUE(IsOk(planField(volume, grid, nullptr, &p)));
  EXPECT_TRUE(p.signedField());
  EXPECT_EQ(p.signName(), "mask-inside");
  EXPECT_DOUBLE_EQ(p.limit_world, 2);

  FieldRequest points;
  points.inside_negative = true;
  EXPECT_TRUE(IsError(planField(points, grid, nullptr, &p), Status::Code::kInvalidArgument, "point seeds are unsigned"));
  points.inside_negative = false;
  points.mesh_sign = SignMethod::kWinding;
  EXPECT_TRUE(IsError(planField(points, grid, nullptr, &p), Status::Code::kInvalidArgument, "winding is for meshes"));
  FieldRequest no_report;  // a caller's bug: the automatic sign needs the mesh's edges
  no_report.seeds = SeedKind::kMesh;
  EXPECT_THROW((void)planField(no_report, grid, nullptr, &p), std::invalid_argument);
}

// The algorithm: the separable EDTs where they compute the same exact field faster, the band where the request asks
// for the propagation itself or the separable passes cannot follow it.
// Names as users give them (the CLI's --sign, the protocol's SignMode): each seed kind takes its own, and refuses the
// others saying which it takes; the algorithm's and the tables' names read back to the same values.
TEST(FieldDefaultsTest, SignAndAlgorithmNamesReadBack) {
  FieldRequest mesh, volume, points;
  mesh.seeds = SeedKind::kMesh;
  volume.seeds = SeedKind::kVolume;
  for (SignMethod m : kSignMethods) {
    EXPECT_TRUE(IsOk(requestSign(signMethodName(m), &mesh)));
    EXPECT_EQ(mesh.mesh_sign, m);
  }
  EXPECT_TRUE(IsOk(requestSign(kMaskInsideSign, &volume)));
  EXPECT_TRUE(volume.inside_negative);
  EXPECT_TRUE(IsOk(requestSign("unsigned", &points)));
  EXPECT_TRUE(IsOk(requestSign("auto", &points)));
  EXPECT_FALSE(points.mesh_sign || points.inside_negative) << "points keep the planner's default";
  EXPECT_TRUE(IsError(requestSign(kMaskInsideSign, &mesh), Status::Code::kInvalidArgument,
                      "mask-inside is for volume seeds; meshes take auto, pseudonormal, winding, parity or unsigned"));
  EXPECT_TRUE(IsError(requestSign("winding", &volume), Status::Code::kInvalidArgument,
                      "winding is for meshes; volume seeds take auto, unsigned or mask-inside"));
  EXPECT_TRUE(IsError(requestSign("signed", &points), Status::Code::kInvalidArgument, "unknown sign 'signed'"));
  for (FieldAlgorithm a : {FieldAlgorithm::kBand, FieldAlgorithm::kSeparable})
    EXPECT_EQ(parseAlgorithm(algorithmName(a)), a);
  EXPECT_FALSE(parseAlgorithm("fast"));
  for (StencilKind k : kStencilKinds) EXPECT_EQ(parseStencil(stencilName(k)), k);
  for (PropagationMode m : kPropagationModes) {
    PropagationMode read;
    EXPECT_TRUE(parseMode(modeName(m), &read));
    EXPECT_EQ(read, m);
  }
}

TEST(FieldDefaultsTest, PlannerPicksTheSeparableEdtsOnlyWhereTheyDeliverTheSameField) {
  const Grid grid({0, 0, 0}, 1, {64, 64, 64});
  using Change = std::function<void(FieldRequest&)>;
  struct Case {
    const char* what;
    SeedKind seeds;  // points: two, on two planes, unless the change says otherwise
    Change change;
    FieldAlgorithm expect;
    bool separable_applies;  ///< an explicit separable request is honoured (else refused)
  };
  const Change none = [](FieldRequest&) {};
  const Change limit = [](FieldRequest& r) { r.limit_voxels = 5; };
  const Change stencil = [](FieldRequest& r) { r.stencil = StencilKind::kFcc12; };
  const Change paper = [](FieldRequest& r) { r.mode = PropagationMode::kPaper; };
  const Change second_ring = [](FieldRequest& r) { r.second_ring = true; };
  const Change closest = [](FieldRequest& r) { r.closest_features = true; };
  const auto volume = SeedKind::kVolume, points = SeedKind::kPoints;
  const auto separable = FieldAlgorithm::kSeparable, band = FieldAlgorithm::kBand;
  const Case cases[] = {
      {"volume", volume, none, separable, true},
      {"volume, limit", volume, limit, separable, true},
      {"volume, stencil", volume, stencil, band, false},
      {"volume, paper", volume, paper, band, false},
      {"volume, second ring", volume, second_ring, band, false},
      {"volume, closest (the propagation's sites)", volume, closest, band, false},
      {"two points", points, none, separable, true},
      {"two points, closest (carried by the passes)", points, closest, separable, true},
      {"two points, limit (the band's work follows it)", points, limit, band, false},
      {"two points, stencil", points, stencil, band, false},
      {"two points, paper", points, paper, band, false},
      {"two points, second ring", points, second_ring, band, false},
      {"points, layout unknown", points, [](FieldRequest& r) { r.point_layout.reset(); }, band, true},
      {"points on 40 of 64 planes", points, [](FieldRequest& r) { r.point_layout = PointLayout{40, 40, 40}; }, band,
       true},
  };
  for (const Case& c : cases) {
    FieldRequest r;
    r.seeds = c.seeds;
    if (c.seeds == points) r.point_layout = PointLayout{2, 2, 2};
    c.change(r);
    FieldPlan p;
    ASSERT_TRUE(IsOk(planField(r, grid, nullptr, &p))) << c.what;
    EXPECT_EQ(p.algorithm, c.expect) << c.what;
    // An explicit choice wins where it applies (what a coordinator sends its replicas), and is refused where not.
    r.algorithm = FieldAlgorithm::kBand;
    ASSERT_TRUE(IsOk(planField(r, grid, nullptr, &p))) << c.what;
    EXPECT_EQ(p.algorithm, band) << c.what;
    r.algorithm = separable;
    const Status s = planField(r, grid, nullptr, &p);
    if (c.separable_applies) {
      EXPECT_TRUE(IsOk(s)) << c.what;
      EXPECT_EQ(p.algorithm, separable) << c.what;
    } else {
      EXPECT_TRUE(IsError(s, Status::Code::kInvalidArgument, "algorithm: separable applies")) << c.what;
    }
  }
}

// Label volumes: the multi-label EDT and nearest labels are the separable EDT's, and the planner says so; anisotropic
// volumes take it too; anisotropic meshes get cubic26 (fcc12's odd half assumes equal axes).
TEST(FieldDefaultsTest, LabelsAndNearestLabelsAreTheSeparableEdtsAndSayWhatTheyCannotDo) {
  const Grid cubic({0, 0, 0}, 1, {32, 32, 32});
  const Grid aniso({0, 0, 0}, Vec3d{0.5, 0.5, 2.5}, {32, 32, 32});
  FieldRequest r;
  r.seeds = SeedKind::kVolume;
  FieldPlan p;
  ASSERT_TRUE(IsOk(planField(r, aniso, nullptr, &p)));
  EXPECT_EQ(p.algorithm, FieldAlgorithm::kSeparable);
  r.labels = true;
  r.black_border = true;
  ASSERT_TRUE(IsOk(planField(r, cubic, nullptr, &p)));
  EXPECT_EQ(p.algorithm, FieldAlgorithm::kSeparable);
  EXPECT_TRUE(p.volumeMeasure().labels);
  EXPECT_TRUE(p.volumeMeasure().black_border);
  EXPECT_FALSE(p.signedField());
  EXPECT_NE(p.algorithmDescription().find("labels: each voxel"), std::string::npos);
  const Status::Code kInvalid = Status::Code::kInvalidArgument;
  auto refused = [&](const FieldRequest& req, const char* why) {
    FieldPlan q;
    EXPECT_TRUE(IsError(planField(req, cubic, nullptr, &q), kInvalid, why)) << why;
  };
  FieldRequest x = r;
  x.stencil = StencilKind::kCubic26;
  refused(x, "labels: only the separable EDT computes it");
  x = r;
  x.algorithm = FieldAlgorithm::kBand;
  refused(x, "labels: only the separable EDT computes it");
  x = r;
  x.inside_negative = true;
  refused(x, "labels: the multi-label EDT is unsigned");
  x = r;
  x.nearest_label = true;
  refused(x, "labels: the multi-label EDT has no closest features");
  x = FieldRequest{};
  x.seeds = SeedKind::kVolume;
  x.black_border = true;
  refused(x, "black border: it applies to the multi-label EDT");
  x = FieldRequest{};
  x.seeds = SeedKind::kPoints;
  x.nearest_label = true;
  refused(x, "are for volume seeds");
  x = FieldRequest{};
  x.seeds = SeedKind::kVolume;
  x.nearest_label = true;
  ASSERT_TRUE(IsOk(planField(x, cubic, nullptr, &p)));
  EXPECT_EQ(p.algorithm, FieldAlgorithm::kSeparable);
  EXPECT_EQ(p.closestFeatureName(), "label");
  EXPECT_TRUE(p.runOptions().closest_features);
  x.closest_features = true;
  refused(x, "nearest label and closest features exclude each other");
  x.closest_features = false;
  x.mode = PropagationMode::kPaper;
  refused(x, "nearest label: only the separable EDT computes it");
  // Meshes: fcc12 on cubic grids, cubic26 on anisotropic ones.
  TriangleMesh tri{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  MeshReport report;
  ASSERT_TRUE(IsOk(validateMesh(&tri, &report)));
  FieldRequest m;
  m.seeds = SeedKind::kMesh;
  ASSERT_TRUE(IsOk(planField(m, cubic, &report, &p)));
  EXPECT_EQ(p.stencil, StencilKind::kFcc12);
  ASSERT_TRUE(IsOk(planField(m, aniso, &report, &p)));
  EXPECT_EQ(p.stencil, StencilKind::kCubic26);
}

TEST(FieldDefaultsTest, AutoSignIsPseudonormalForClosedAndWindingForOpenMeshes) {
  MeshReport closed;
  std::string why;
  EXPECT_EQ(resolveSignMethod(SignMethod::kAuto, closed, &why), SignMethod::kPseudonormal);
  EXPECT_EQ(why, "auto: the mesh is closed");
  MeshReport open;
  open.boundary_edges = 12;
  EXPECT_EQ(resolveSignMethod(SignMethod::kAuto, open, &why), SignMethod::kWinding);
  EXPECT_EQ(why, "auto: the mesh is not closed (12 boundary edges)");
  MeshReport non_manifold;
  non_manifold.non_manifold_edges = 3;
  EXPECT_EQ(resolveSignMethod(SignMethod::kAuto, non_manifold, &why), SignMethod::kWinding);
  EXPECT_NE(why.find("3 non-manifold edges"), std::string::npos);
  EXPECT_EQ(resolveSignMethod(SignMethod::kParity, open, &why), SignMethod::kParity);
  EXPECT_EQ(why, "requested");
  // Closed parts whose bounding boxes overlap may cross or nest, where the pseudonormal test is wrong.
  MeshReport parts;
  parts.components = 2;
  EXPECT_EQ(resolveSignMethod(SignMethod::kAuto, parts, &why), SignMethod::kPseudonormal);
  EXPECT_EQ(why, "auto: the mesh is closed");
  parts.components_overlap = true;
  EXPECT_EQ(resolveSignMethod(SignMethod::kAuto, parts, &why), SignMethod::kWinding);
  EXPECT_EQ(why, "auto: the mesh is closed but its parts overlap (2 parts, bounding boxes intersect)");
  EXPECT_EQ(resolveSignMethod(SignMethod::kPseudonormal, parts, &why), SignMethod::kPseudonormal);
  SignMethod parsed;
  ASSERT_TRUE(parseSignMethod("auto", &parsed));
  EXPECT_EQ(parsed, SignMethod::kAuto);
  EXPECT_EQ(kDefaultMeshSign, SignMethod::kAuto);
}

// Signs of the open teapot against the brute-force winding number (inside where it exceeds 1/2): the default must not
// show the pseudonormal test's wrong-sign patches near the holes.
TEST(FieldDefaultsTest, OpenTeapotGetsTheWindingSignByDefault) {
  TriangleMesh mesh;
  MeshReport report;
  ASSERT_TRUE(IsOk(loadMesh(DISTBAND_TEST_DATA_DIR "/meshes/teapot.obj", &mesh, &report)));
  ASSERT_FALSE(report.closed());
  MeshGridOptions go;
  go.resolution = 40;
  Grid grid;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, go, {kInf, 3}, &grid)));
  auto wrongSigns = [&](SignMethod requested) {
    MeshSeedOptions so;
    so.sign = resolveSignMethod(requested, report, nullptr);
    so.limit_voxels = 3;
    Seeds seeds;
    EXPECT_TRUE(IsOk(makeMeshSeeds(grid, mesh, so, &seeds)));
    BandOptions eo;
    eo.limit_world = 3 * grid.voxelSize();
    int64_t wrong = 0, total = 0;
    computeBandField(grid, seeds, eo, [&](SegmentBricks&& s) {
      for (const Brick& b : s.bricks)
        for (int i = 0; i < kBrickVoxels; ++i) {
          const Coord c = b.origin + brickLocal(i);
          if (!b.mask.test(i) || !grid.contains(c) || std::abs(b.values[i]) < 0.5 * grid.voxelSize()) continue;
          const bool inside = testing::bruteWinding(mesh, grid.worldOf(c)) > 0.5;
          wrong += (b.values[i] < 0) != inside;
          ++total;
        }
    });
    std::printf("teapot, sign %s: %lld of %lld voxels (|d| >= h/2) disagree with the winding number\n",
                std::string(signMethodName(resolveSignMethod(requested, report, nullptr))).c_str(), (long long)wrong,
                (long long)total);
    EXPECT_GT(total, 5000);
    return wrong;
  };
  const int64_t pseudonormal = wrongSigns(SignMethod::kPseudonormal);
  const int64_t automatic = wrongSigns(kDefaultMeshSign);
  EXPECT_GT(pseudonormal, 0);  // the patch the issue reported: the check can see it
  EXPECT_EQ(automatic, 0);
}

// Every delivered voxel's closest feature gives exactly the delivered distance.
TEST(FieldDefaultsTest, ClosestFeaturesGiveTheDeliveredDistance) {
  const Grid grid({0, 0, 0}, 0.5, {40, 36, 30});
  BandOptions eo;
  eo.closest_features = true;
  eo.limit_world = 4;
  eo.segment_length_world = 1;
  // at_most: the value may exceed the feature's distance (paper mode propagates the band's closest points, which
  // lie on the feature: the feature is at least that close).
  auto check = [&](const Seeds& seeds, const std::function<double(int64_t id, const Coord& c)>& distance,
                   const char* what, bool at_most = false) {
    int64_t voxels = 0, mismatches = 0;
    double worst = 0;
    computeBandField(grid, seeds, eo, [&](SegmentBricks&& s) {
      for (const Brick& b : s.bricks) {
        ASSERT_EQ(b.closest.size(), size_t(kBrickVoxels));
        for (int i = 0; i < kBrickVoxels; ++i) {
          const Coord c = b.origin + brickLocal(i);
          if (!b.mask.test(i) || !grid.contains(c)) continue;
          ++voxels;
          ASSERT_GE(b.closest[size_t(i)], 0) << what;
          const double diff = distance(b.closest[size_t(i)], c) - std::abs(b.values[i]);
          const double err = at_most ? std::max(0.0, diff) : std::abs(diff);
          worst = std::max(worst, err);
          mismatches += err > 1e-5;
        }
      }
    });
    std::printf("%s: %lld voxels, largest |distance(feature) - value| %.3g\n", what, (long long)voxels, worst);
    EXPECT_GT(voxels, 1000) << what;
    EXPECT_EQ(mismatches, 0) << what;
  };

  const std::vector<Vec3d> points = {{3, 4, 5}, {12.2, 9.1, 7.7}, {6, 14, 10.5}, {15, 2, 3}};
  Seeds point_seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, points, &point_seeds)));
  check(point_seeds, [&](int64_t id, const Coord& c) { return (grid.worldOf(c) - points[size_t(id)]).length(); },
        "points");

  std::vector<uint8_t> mask(size_t(grid.voxelCount()), 0);
  for (int z = 8; z < 20; ++z)
    for (int y = 10; y < 16; ++y)
      for (int x = 5 + (z & 3); x < 25; ++x) mask[size_t(grid.denseIndex({x, y, z}))] = 1;
  auto voxelDistance = [&](int64_t id, const Coord& c) {
    const Coord d = grid.dims();
    const Coord s{int(id % d.x), int(id / d.x % d.y), int(id / (int64_t(d.x) * d.y))};
    return (grid.worldOf(c) - grid.worldOf(s)).length();
  };
  for (bool signed_volume : {false, true}) {
    Seeds volume_seeds;
    ASSERT_TRUE(IsOk(makeVolumeSeeds(grid, LabelVolume::ofMask(grid.dims(), mask), signed_volume, &volume_seeds)));
    // Unsigned: the feature is a seed voxel. Signed: a voxel on the other side of the mask's boundary.
    check(volume_seeds, [&](int64_t id, const Coord& c) {
      EXPECT_EQ(mask[size_t(id)] != 0, signed_volume ? mask[size_t(grid.denseIndex(c))] == 0 : true);
      return voxelDistance(id, c);
    }, signed_volume ? "signed volume" : "volume");
  }

  const TriangleMesh sphere = testing::makeSphereMesh({10, 9, 7.5}, 5, 16, 32);
  for (MeshSiteMode mode : {MeshSiteMode::kExactFeature, MeshSiteMode::kPaper}) {
    MeshSeedOptions so;
    so.mode = mode;
    so.sign = SignMethod::kUnsigned;
    so.limit_voxels = eo.limit_world / grid.voxelSize();
    Seeds mesh_seeds;
    ASSERT_TRUE(IsOk(makeMeshSeeds(grid, sphere, so, &mesh_seeds)));
    BandOptions saved = eo;
    if (mode == MeshSiteMode::kPaper) eo.mode = PropagationMode::kPaper;
    check(mesh_seeds, [&](int64_t id, const Coord& c) {
      TriangleMesh one;  // the recorded triangle alone, measured by the brute-force oracle
      for (uint32_t v : sphere.triangles[size_t(id)]) one.vertices.push_back(sphere.vertices[v]);
      one.triangles = {{0, 1, 2}};
      return testing::bruteDistance(one, grid.worldOf(c));
    }, mode == MeshSiteMode::kPaper ? "mesh, paper mode" : "mesh, exact-feature mode", mode == MeshSiteMode::kPaper);
    eo = saved;
  }
}

}  // namespace
}  // namespace distband
