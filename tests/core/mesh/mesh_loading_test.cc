// Tests for core/mesh/triangle_mesh (loading and validation) and core/mesh/mesh_grid.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/status.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

class MeshLoadingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("distband_mesh_loading_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& bytes) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  // Loading must fail with `code` and a message naming the file and containing `what`.
  void expectError(const std::string& path, const std::string& what,
                   Status::Code code = Status::Code::kInvalidArgument) {
    TriangleMesh mesh;
    MeshReport report;
    const Status s = loadMesh(path, &mesh, &report);
    EXPECT_TRUE(IsError(s, code, path));
    EXPECT_TRUE(IsError(s, code, what));
    EXPECT_TRUE(mesh.triangles.empty());
  }
  fs::path dir_;
};

// A unit tetrahedron, outward, in each supported format.
const char* kTetObj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
const char* kTetOff = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
const char* kTetPly =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
    "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

std::string tetStlAscii() {
  const double v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string s = "solid tet\n";
  for (const auto& t : f) {
    s += "facet normal 0 0 0\nouter loop\n";
    for (int k : t) s += "vertex " + std::to_string(v[k][0]) + " " + std::to_string(v[k][1]) + " " +
                         std::to_string(v[k][2]) + "\n";
    s += "endloop\nendfacet\n";
  }
  return s + "endsolid tet\n";
}

std::string tetStlBinary(uint32_t declared = 4, int written = 4) {
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string s(80, ' ');
  s.append(reinterpret_cast<const char*>(&declared), 4);
  for (int t = 0; t < written; ++t) {
    const float n[3] = {0, 0, 0};
    s.append(reinterpret_cast<const char*>(n), 12);
    for (int k : f[t]) s.append(reinterpret_cast<const char*>(v[k]), 12);
    s.append(2, '\0');
  }
  return s;
}

TEST_F(MeshLoadingTest, EveryFormatLoadsTheSameClosedTetrahedron) {
  const std::string paths[] = {write("tet.obj", kTetObj), write("tet.off", kTetOff), write("tet.ply", kTetPly),
                               write("tet_ascii.stl", tetStlAscii()), write("tet_binary.stl", tetStlBinary())};
  for (const std::string& path : paths) {
    TriangleMesh mesh;
    MeshReport report;
    ASSERT_TRUE(IsOk(loadMesh(path, &mesh, &report))) << path;
    EXPECT_EQ(report.vertices, 4) << path;  // STL repeats corners per facet: welded back to 4
    EXPECT_EQ(report.triangles, 4) << path;
    EXPECT_EQ(report.boundary_edges, 0) << path;
    EXPECT_EQ(report.non_manifold_edges, 0) << path;
    EXPECT_TRUE(report.closed()) << path;
    EXPECT_EQ(report.bbox_min, (Vec3d{0, 0, 0})) << path;
    EXPECT_EQ(report.bbox_max, (Vec3d{1, 1, 1})) << path;
    // Orientation is preserved: the signed volume of an outward tetrahedron is +1/6.
    double volume = 0;
    for (const auto& t : mesh.triangles)
      volume += mesh.vertices[t[0]].dot(mesh.vertices[t[1]].cross(mesh.vertices[t[2]])) / 6.0;
    EXPECT_NEAR(volume, 1.0 / 6.0, 1e-6) << path;
  }
}

TEST_F(MeshLoadingTest, BundledMeshesReportTheirTopology) {
  TriangleMesh bunny, teapot, fandisk;
  MeshReport rb, rt, rf;
  ASSERT_TRUE(IsOk(loadMesh(DISTBAND_TEST_DATA_DIR "/meshes/bunny.obj", &bunny, &rb)));
  EXPECT_EQ(rb.triangles, 3674);
  EXPECT_TRUE(rb.closed()) << rb.summary();
  ASSERT_TRUE(IsOk(loadMesh(DISTBAND_TEST_DATA_DIR "/meshes/teapot.obj", &teapot, &rt)));
  EXPECT_EQ(rt.triangles, 992);
  EXPECT_GT(rt.boundary_edges, 0) << rt.summary();  // the teapot is open
  ASSERT_TRUE(IsOk(loadMesh(DISTBAND_TEST_DATA_DIR "/meshes/fandisk.off", &fandisk, &rf)));
  EXPECT_EQ(rf.triangles, 12946);
  EXPECT_TRUE(rf.closed()) << rf.summary();
}

TEST_F(MeshLoadingTest, DegenerateTrianglesAreCountedAndSkipped) {
  // A repeated corner and a collinear (zero-area) triangle besides the tetrahedron.
  const std::string path = write("degenerate.obj", std::string(kTetObj) + "v 2 0 0\nf 1 1 2\nf 1 2 5\n");
  TriangleMesh mesh;
  MeshReport report;
  ASSERT_TRUE(IsOk(loadMesh(path, &mesh, &report)));
  EXPECT_EQ(report.triangles, 4);
  EXPECT_EQ(report.degenerate, 2);
  EXPECT_EQ(report.vertices, 4);  // the unreferenced vertex is dropped
  EXPECT_NE(report.summary().find("2 degenerate"), std::string::npos) << report.summary();
}

TEST_F(MeshLoadingTest, OpenAndNonManifoldEdgesAreCounted) {
  // Three triangles on one edge (non-manifold), everything else boundary.
  const std::string path = write("fan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 2 5\n");
  TriangleMesh mesh;
  MeshReport report;
  ASSERT_TRUE(IsOk(loadMesh(path, &mesh, &report)));
  EXPECT_EQ(report.non_manifold_edges, 1);
  EXPECT_EQ(report.boundary_edges, 6);
  EXPECT_FALSE(report.closed());
}

TEST_F(MeshLoadingTest, TruncatedFilesAreClearErrors) {
  expectError(write("short.stl", tetStlBinary(4, 2)), "truncated or not STL");
  expectError(write("short.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n"), "bytes follow");
  // An OBJ cut in the middle of a face line leaves a 2-index face.
  expectError(write("short.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2"), "at least 3 corners");
  // A PLY whose body ends before its declared faces.
  expectError(write("short.ply", std::string(kTetPly).substr(0, std::strlen(kTetPly) - 40)), "PLY element");
}

TEST_F(MeshLoadingTest, NonFiniteCoordinatesAreClearErrors) {
  expectError(write("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 2 3\nf 1 2 4\n"), "finite");
  expectError(write("inf.off", "OFF\n3 1 0\n0 0 0\n1e999 0 0\n0 1 0\n3 0 1 2\n"), "finite");
}

TEST_F(MeshLoadingTest, OutOfRangeIndicesAreClearErrors) {
  expectError(write("oor.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"), "out of range");
  expectError(write("oor.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n"), "refers to vertex 5");
  std::string ply = kTetPly;
  ply.replace(ply.rfind("3 1 2 3"), 7, "3 1 2 9");
  expectError(write("oor.ply", ply), "out of range");
}

TEST_F(MeshLoadingTest, EmptyMissingAndUnsupportedFilesAreClearErrors) {
  expectError(write("empty.obj", ""), "empty");
  expectError(write("comments.obj", "# nothing here\n"), "no triangles");
  expectError(write("points.obj", "v 0 0 0\nv 1 0 0\n"), "no triangles");
  expectError((dir_ / "missing.obj").string(), "cannot open: No such file", Status::Code::kNotFound);
  expectError(write("mesh.xyz", kTetObj), "unsupported mesh format");
  expectError(write("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"), "degenerate");
}

TEST(ValidateMeshTest, RejectsBadInMemoryMeshes) {
  TriangleMesh empty;
  EXPECT_TRUE(IsError(validateMesh(&empty, nullptr), Status::Code::kInvalidArgument, "no triangles"));
  TriangleMesh oor{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 3}}};
  EXPECT_TRUE(IsError(validateMesh(&oor, nullptr), Status::Code::kInvalidArgument, "vertex 3"));
  TriangleMesh nan{{{0, 0, 0}, {NAN, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  EXPECT_TRUE(IsError(validateMesh(&nan, nullptr), Status::Code::kInvalidArgument, "non-finite"));
}

// Orientation repair. Vertex ids are renumbered by validateMesh, so faces are compared by corner positions.
using FacePositions = std::vector<std::array<Vec3d, 3>>;
FacePositions facePositions(const TriangleMesh& m) {
  FacePositions f;
  for (const auto& t : m.triangles) f.push_back({m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]]});
  return f;
}
bool samePositions(const std::array<Vec3d, 3>& a, const std::array<Vec3d, 3>& b) {
  for (int i = 0; i < 3; ++i)
    if (a[i].x != b[i].x || a[i].y != b[i].y || a[i].z != b[i].z) return false;
  return true;
}
// Every edge's faces run it in opposite directions (each directed edge once, and its reverse present).
bool consistentlyOriented(const TriangleMesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : m.triangles)
    for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
  for (const auto& [edge, count] : directed)
    if (count != 1 || !directed.count({edge.second, edge.first})) return false;
  return true;
}
double signedVolume(const TriangleMesh& m, size_t first = 0, size_t end = SIZE_MAX) {
  double v = 0;
  for (size_t i = first; i < std::min(end, m.triangles.size()); ++i) {
    const auto& t = m.triangles[i];
    v += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6;
  }
  return v;
}
void flipFace(TriangleMesh* m, size_t i) { std::swap(m->triangles[i][1], m->triangles[i][2]); }
// A closed outward UV sphere, and the same validated (the reference for positions).
TriangleMesh sphere(const Vec3d& c = {0.1, -0.2, 0.3}) { return testing::makeSphereMesh(c, 1.0, 8, 16); }

TEST(ValidateMeshTest, AFlippedPatchOfAClosedMeshIsReorientedOutward) {
  TriangleMesh reference = sphere();
  ASSERT_TRUE(IsOk(validateMesh(&reference, nullptr)));
  const size_t n = reference.triangles.size();
  ASSERT_TRUE(consistentlyOriented(reference));
  // A small patch (faces 0..19) and a large one (all but the last 20): the repaired mesh is unique (consistent and
  // outward), so the faces flipped are exactly the patch, whichever side the traversal starts on.
  for (size_t patch_end : {size_t(20), n - 20}) {
    TriangleMesh m = sphere();
    for (size_t i = 0; i < patch_end; ++i) flipFace(&m, i);
    MeshReport r;
    ASSERT_TRUE(IsOk(validateMesh(&m, &r)));
    EXPECT_TRUE(r.closed()) << r.summary();
    EXPECT_EQ(r.reoriented_faces, int64_t(patch_end)) << r.summary();
    EXPECT_NE(r.summary().find(std::to_string(patch_end) + " faces re-oriented"), std::string::npos) << r.summary();
    EXPECT_TRUE(consistentlyOriented(m));
    EXPECT_GT(signedVolume(m), 0);
    EXPECT_NEAR(signedVolume(m), signedVolume(reference), 1e-12);
    const FacePositions got = facePositions(m), want = facePositions(reference);
    ASSERT_EQ(got.size(), want.size());
    for (size_t i = 0; i < n; ++i) EXPECT_TRUE(samePositions(got[i], want[i])) << "face " << i;
  }
}

TEST(ValidateMeshTest, AConsistentlyInwardMeshIsNotFlipped) {
  TriangleMesh m = sphere();
  for (size_t i = 0; i < m.triangles.size(); ++i) flipFace(&m, i);
  TriangleMesh inward = m;
  ASSERT_TRUE(IsOk(validateMesh(&inward, nullptr)));  // nothing to repair: the reference is itself
  MeshReport r;
  ASSERT_TRUE(IsOk(validateMesh(&m, &r)));
  EXPECT_TRUE(r.closed());
  EXPECT_EQ(r.reoriented_faces, 0);
  EXPECT_EQ(r.summary().find("re-oriented"), std::string::npos) << r.summary();
  EXPECT_LT(signedVolume(m), 0);  // today's behaviour: consistent meshes are taken as they are
  EXPECT_EQ(m.triangles, inward.triangles);
}

TEST(ValidateMeshTest, OpenNonManifoldAndNonOrientableMeshesAreNotReoriented) {
  auto expectUntouched = [](TriangleMesh m, const char* what) -> MeshReport {
    MeshReport r;
    const TriangleMesh before = m;
    EXPECT_TRUE(IsOk(validateMesh(&m, &r))) << what;
    EXPECT_EQ(r.reoriented_faces, 0) << what << ": " << r.summary();
    const FacePositions got = facePositions(m), want = facePositions(before);
    EXPECT_EQ(got.size(), want.size()) << what;
    for (size_t i = 0; i < std::min(got.size(), want.size()); ++i)
      EXPECT_TRUE(samePositions(got[i], want[i])) << what << ": face " << i;
    return r;
  };
  // Open: a sphere with a face removed and a patch flipped.
  TriangleMesh open = sphere();
  open.triangles.pop_back();
  for (size_t i = 0; i < 20; ++i) flipFace(&open, i);
  EXPECT_EQ(expectUntouched(open, "open").boundary_edges, 3);
  // Non-manifold: a sphere with a patch flipped and a face doubled (its three edges then have three faces).
  TriangleMesh fin = sphere();
  for (size_t i = 0; i < 20; ++i) flipFace(&fin, i);
  fin.triangles.push_back(fin.triangles[40]);
  EXPECT_EQ(expectUntouched(fin, "non-manifold").non_manifold_edges, 3);
  // Non-orientable but closed: the 6-vertex projective plane (every edge in exactly two faces, some necessarily
  // run the same way), vertices on the moment curve so that no triangle is degenerate.
  TriangleMesh rp2;
  for (int i = 1; i <= 6; ++i) rp2.vertices.push_back({double(i), double(i * i), double(i * i * i)});
  rp2.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}, {0, 5, 1},
                   {1, 2, 4}, {2, 3, 5}, {3, 4, 1}, {4, 5, 2}, {5, 1, 3}};
  EXPECT_TRUE(expectUntouched(rp2, "projective plane").closed());
}

TEST(ValidateMeshTest, OnlyTheInconsistentComponentIsReoriented) {
  // First component: consistent but inward (kept); second, disjoint: outward with a flipped patch (repaired).
  TriangleMesh a = sphere({0, 0, 0}), b = sphere({5, 0, 0});
  for (size_t i = 0; i < a.triangles.size(); ++i) flipFace(&a, i);
  for (size_t i = 10; i < 30; ++i) flipFace(&b, i);
  const size_t na = a.triangles.size();
  TriangleMesh both = a;
  const uint32_t offset = uint32_t(a.vertices.size());
  both.vertices.insert(both.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto t : b.triangles) both.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  TriangleMesh reference = both;
  for (size_t i = na + 10; i < na + 30; ++i) flipFace(&reference, i);  // what the repair should give
  ASSERT_TRUE(IsOk(validateMesh(&reference, nullptr)));
  MeshReport r;
  ASSERT_TRUE(IsOk(validateMesh(&both, &r)));
  EXPECT_TRUE(r.closed());
  EXPECT_EQ(r.reoriented_faces, 20) << r.summary();
  EXPECT_LT(signedVolume(both, 0, na), 0);
  EXPECT_GT(signedVolume(both, na), 0);
  const FacePositions got = facePositions(both), want = facePositions(reference);
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) EXPECT_TRUE(samePositions(got[i], want[i])) << "face " << i;
}

// The report's parts (connected through shared vertices) and whether their bounding boxes overlap, which decides
// the automatic sign of a closed mesh (core/seeds/mesh_sign.h): one part; parts in a row, disjoint (the sweep
// drops each part once passed); the same row with one more part overlapping the last, or nested in the first, or
// touching one at a face; two parts sharing only a vertex (one part).
TEST(ValidateMeshTest, PartsAndTheirOverlapAreReported) {
  auto join = [](TriangleMesh a, const TriangleMesh& b) {
    const uint32_t offset = uint32_t(a.vertices.size());
    a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
    for (auto t : b.triangles) a.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
    return a;
  };
  auto box = [](double x, double y = 0, double size = 1) {
    return testing::makeBoxMesh({x, y, 0}, {x + size, y + size, size});
  };
  auto report = [](TriangleMesh m) {
    MeshReport r;
    EXPECT_TRUE(IsOk(validateMesh(&m, &r)));
    return r;
  };
  const MeshReport one = report(box(0));
  EXPECT_EQ(one.components, 1);
  EXPECT_FALSE(one.components_overlap);
  EXPECT_EQ(one.summary().find("parts"), std::string::npos) << one.summary();
  TriangleMesh row = box(0);
  for (int i = 1; i < 40; ++i) row = join(row, box(2.0 * i, (i % 3) * 0.5));  // gaps of 1 along x
  const MeshReport disjoint = report(row);
  EXPECT_EQ(disjoint.components, 40);
  EXPECT_FALSE(disjoint.components_overlap) << disjoint.summary();
  EXPECT_NE(disjoint.summary().find(", 40 parts"), std::string::npos) << disjoint.summary();
  EXPECT_EQ(disjoint.summary().find("overlap"), std::string::npos) << disjoint.summary();
  const MeshReport crossing = report(join(row, box(78.5, 0.5)));  // into the last box (x 78..79, y 0..1)
  EXPECT_EQ(crossing.components, 41);
  EXPECT_TRUE(crossing.components_overlap);
  EXPECT_NE(crossing.summary().find(", 41 parts (bounding boxes overlap)"), std::string::npos) << crossing.summary();
  EXPECT_TRUE(report(join(row, box(0.25, 0.25, 0.5))).components_overlap);  // nested in the first
  EXPECT_TRUE(report(join(row, box(-1, 0.5))).components_overlap);          // touching the first at x = 0
  EXPECT_FALSE(report(join(row, box(-1.5, 0.5))).components_overlap);
  // Two boxes sharing one corner are one part (triangles sharing a vertex are connected).
  const MeshReport corner = report(join(box(0), testing::makeBoxMesh({1, 1, 1}, {2, 2, 2})));
  EXPECT_EQ(corner.components, 1);
  EXPECT_TRUE(corner.closed()) << corner.summary();
  EXPECT_FALSE(corner.components_overlap);
  std::vector<uint32_t> part;
  EXPECT_EQ(findMeshParts(6, {{3, 4, 1}, {0, 2, 0}}, &part), 3);  // {1, 3, 4}, {0, 2} and the unused 5
  EXPECT_EQ(part, (std::vector<uint32_t>{0, 1, 0, 1, 1, 2}));
}

// Slivers side by side: their boxes all overlap along the sweep's axis (x, the longest) and nowhere else, so each part
// is tested against every earlier one. Few of them are answered exactly (disjoint); past the sweep's budget (64 tests
// a part plus 2^20) the answer is the conservative "overlap", so the quadratic sweep never runs on.
TEST(ValidateMeshTest, ThePartsSweepIsBoundedAndErrsTowardsOverlap) {
  auto slivers = [](int n) {
    TriangleMesh m;
    for (int i = 0; i < n; ++i) {
      const double y = 2.0 * (i % 64), z = 2.0 * (i / 64);
      const uint32_t v = uint32_t(m.vertices.size());
      m.vertices.insert(m.vertices.end(), {{0, y, z}, {1000, y, z}, {0, y + 1, z + 1}});
      m.triangles.push_back({v, v + 1, v + 2});
    }
    MeshReport r;
    EXPECT_TRUE(IsOk(validateMesh(&m, &r)));
    EXPECT_EQ(r.components, n);
    return r.components_overlap;
  };
  EXPECT_FALSE(slivers(300));  // 44 850 box tests: exact
  EXPECT_TRUE(slivers(3000));  // 4.5 million would be needed: the budget stops the sweep
}

TEST(MeshGridTest, ResolutionSpansTheLongestSideIncludingPadding) {
  TriangleMesh mesh{{{0, 0, 0}, {10, 0, 0}, {0, 5, 0}, {0, 0, 2}}, {{0, 1, 2}, {0, 1, 3}}};
  Grid g;
  MeshGridOptions o;
  o.resolution = 64;
  o.padding_voxels = 3;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, o, {}, &g)));
  EXPECT_EQ(g.dims().x, 64);
  EXPECT_NEAR(g.voxelSize(), 10.0 / 57, 1e-12);
  EXPECT_NEAR(g.origin().x, -3 * g.voxelSize(), 1e-12);
  // The mesh's far corner sits padding voxels inside the last voxel.
  EXPECT_NEAR(g.indexOf({10, 0, 0}).x, 60, 1e-9);
  EXPECT_GE(g.indexOf({0, 5, 2}).y, 0);
  EXPECT_LE(g.indexOf({0, 5, 0}).y, g.dims().y - 1 - 3);
  EXPECT_LE(g.indexOf({0, 0, 2}).z, g.dims().z - 1 - 3);
}

TEST(MeshGridTest, VoxelSizeAndExplicitBox) {
  TriangleMesh mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  Grid g;
  MeshGridOptions o;
  o.voxel_size = 0.1;
  o.padding_voxels = 0;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, o, {}, &g)));
  EXPECT_EQ(g.dims().x, 11);
  EXPECT_EQ(g.dims().z, 1);
  o.box_min = Vec3d{-1, -1, -1};
  o.box_max = Vec3d{1, 1, 1};
  ASSERT_TRUE(IsOk(gridForMesh(mesh, o, {}, &g)));
  EXPECT_EQ(g.dims().x, 21);
  EXPECT_EQ(g.origin(), (Vec3d{-1, -1, -1}));
}

TEST(MeshGridTest, RejectsBadOptions) {
  TriangleMesh mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  Grid g;
  MeshGridOptions both;
  both.voxel_size = 0.1, both.resolution = 10;
  EXPECT_TRUE(IsError(gridForMesh(mesh, both, {}, &g), Status::Code::kInvalidArgument, "exactly one of voxel size"));
  MeshGridOptions none;
  EXPECT_TRUE(IsError(gridForMesh(mesh, none, {}, &g), Status::Code::kInvalidArgument, "exactly one of voxel size"));
  MeshGridOptions tiny;
  tiny.resolution = 6, tiny.padding_voxels = 3;
  EXPECT_TRUE(IsError(gridForMesh(mesh, tiny, {}, &g), Status::Code::kInvalidArgument, "padding"));
  MeshGridOptions huge;
  huge.voxel_size = 1e-9;
  EXPECT_TRUE(IsError(gridForMesh(mesh, huge, {}, &g), Status::Code::kInvalidArgument, "at most"));
  MeshGridOptions box;
  box.voxel_size = 0.1, box.box_min = Vec3d{1, 1, 1}, box.box_max = Vec3d{0, 0, 0};
  EXPECT_TRUE(IsError(gridForMesh(mesh, box, {}, &g), Status::Code::kInvalidArgument, "max corner must be >= its min"));
}

// Finite numbers whose differences or quotients are not: each once turned a voxel count into NaN, then into an int
// (undefined behaviour, found by the query fuzzer with a box from -1.8e308 to 1).
TEST(MeshGridTest, RejectsBoundsWhoseSizesOverflowOrUnderflow) {
  TriangleMesh mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  Grid g;
  for (const bool by_voxel_size : {false, true}) {
    MeshGridOptions wide;
    if (by_voxel_size)
      wide.voxel_size = 1;
    else
      wide.resolution = 64;
    wide.box_min = Vec3d{-1, -1, -1.7e308};
    wide.box_max = Vec3d{1, 1, 1.7e308};
    EXPECT_TRUE(
        IsError(gridForMesh(mesh, wide, {}, &g), Status::Code::kInvalidArgument, "box's corners are too far apart"));
  }
  const TriangleMesh far{{{0, 0, -1.7e308}, {1, 0, 1.7e308}, {0, 1, 0}}, {{0, 1, 2}}};
  MeshGridOptions by_resolution;
  by_resolution.resolution = 64;
  EXPECT_TRUE(IsError(gridForMesh(far, by_resolution, {}, &g), Status::Code::kInvalidArgument,
                      "mesh's vertices are too far apart"));
  MeshGridOptions subnormal;
  subnormal.resolution = 1000;
  subnormal.box_min = Vec3d{0, 0, 0};
  subnormal.box_max = Vec3d{5e-324, 0, 0};
  EXPECT_TRUE(IsError(gridForMesh(mesh, subnormal, {}, &g), Status::Code::kInvalidArgument, "too small to be split"));
}

}  // namespace
}  // namespace distband
