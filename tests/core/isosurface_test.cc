// Tests for core/io/isosurface: isosurfaces of an OpenVDB sphere level set at distances 0 and 2 — vertex radii,
// orientation (outward), closedness, and the OBJ file parsed back; invalid distances are errors.
#include "core/io/isosurface.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <utility>

#include <gtest/gtest.h>
#include <openvdb/tools/LevelSetSphere.h>

namespace distband {
namespace {

namespace fs = std::filesystem;

constexpr float kRadius = 10.f;
constexpr float kVoxel = 0.25f;
const openvdb::Vec3f kCentre(1.f, -2.f, 3.f);

openvdb::FloatGrid::Ptr makeSphere() {
  // Half width 12 voxels = 3 world units: the band holds the surfaces at distance 0 and 2.
  return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(kRadius, kCentre, kVoxel, 12.f);
}

double signedVolume(const TriangleMeshF& mesh) {
  double v = 0;
  for (const auto& t : mesh.triangles) {
    const auto& a = mesh.vertices[t[0]];
    const auto& b = mesh.vertices[t[1]];
    const auto& c = mesh.vertices[t[2]];
    // (a - centre) . ((b - centre) x (c - centre)) / 6
    const double ax = a[0] - kCentre.x(), ay = a[1] - kCentre.y(), az = a[2] - kCentre.z();
    const double bx = b[0] - kCentre.x(), by = b[1] - kCentre.y(), bz = b[2] - kCentre.z();
    const double cx = c[0] - kCentre.x(), cy = c[1] - kCentre.y(), cz = c[2] - kCentre.z();
    v += (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)) / 6.0;
  }
  return v;
}

/// Every undirected edge is used by exactly two triangles, once in each direction (closed, consistently wound).
bool closedAndConsistent(const TriangleMeshF& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
  for (const auto& [edge, n] : directed) {
    if (n != 1) return false;
    auto it = directed.find({edge.second, edge.first});
    if (it == directed.end() || it->second != 1) return false;
  }
  return true;
}

class IsosurfaceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    dir_ = fs::temp_directory_path() / ("distband_isosurface_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(IsosurfaceTest, SphereSurfacesAtDistanceZeroAndTwo) {
  const openvdb::FloatGrid::Ptr grid = makeSphere();
  ASSERT_NEAR(grid->background(), 3.f, 1e-6);
  for (const double d : {0.0, 2.0}) {
    SCOPED_TRACE(testing::Message() << "distance " << d);
    TriangleMeshF mesh;
    ASSERT_EQ(extractIsosurface(*grid, {d, 0.0}, &mesh), "");
    ASSERT_GT(mesh.triangles.size(), 1000u);
    const double r = kRadius + d;
    double max_err = 0;
    for (const auto& v : mesh.vertices) {
      const double dx = v[0] - kCentre.x(), dy = v[1] - kCentre.y(), dz = v[2] - kCentre.z();
      max_err = std::max(max_err, std::abs(std::sqrt(dx * dx + dy * dy + dz * dz) - r));
    }
    // Trilinear interpolation of an exact distance field: error well below a tenth of a voxel.
    EXPECT_LT(max_err, 0.1 * kVoxel);
    // Outward orientation: the signed volume is positive and close to the ball's (flat facets lose a little).
    const double ball = 4.0 / 3.0 * M_PI * r * r * r;
    const double vol = signedVolume(mesh);
    EXPECT_GT(vol, 0.99 * ball);
    EXPECT_LT(vol, 1.001 * ball);
    EXPECT_TRUE(closedAndConsistent(mesh));
    RecordProperty(d == 0 ? "triangles_d0" : "triangles_d2", int(mesh.triangles.size()));
    std::printf("isosurface D=%g: %zu vertices, %zu triangles, max |radius error| %.5f, volume/ball %.5f\n", d,
                mesh.vertices.size(), mesh.triangles.size(), max_err, vol / ball);
  }
}

TEST_F(IsosurfaceTest, ObjFileParsesBackToTheMesh) {
  const openvdb::FloatGrid::Ptr grid = makeSphere();
  grid->setName("sphere");
  const std::string path = (dir_ / "sphere_2.obj").string();
  TriangleMeshF mesh;
  ASSERT_EQ(writeIsosurfaceObj(path, *grid, {2.0, 0.0}, &mesh), "");
  // Only the OBJ is left: the temporary file was renamed.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);

  std::ifstream in(path);
  ASSERT_TRUE(in);
  std::string line;
  size_t v = 0, f = 0, comments = 0;
  bool header_names_grid = false;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "#") {
      ++comments;
      header_names_grid |= line.find("'sphere'") != std::string::npos && line.find("distance 2") != std::string::npos;
    } else if (tag == "v") {
      float x, y, z;
      ASSERT_TRUE(ls >> x >> y >> z) << line;
      ASSERT_LT(v, mesh.vertices.size());
      // Written with round-trip precision.
      EXPECT_EQ(x, mesh.vertices[v][0]);
      EXPECT_EQ(y, mesh.vertices[v][1]);
      EXPECT_EQ(z, mesh.vertices[v][2]);
      ++v;
    } else if (tag == "f") {
      long a, b, c;
      ASSERT_TRUE(ls >> a >> b >> c) << line;
      ASSERT_LT(f, mesh.triangles.size());
      EXPECT_EQ(a, long(mesh.triangles[f][0]) + 1);
      EXPECT_EQ(b, long(mesh.triangles[f][1]) + 1);
      EXPECT_EQ(c, long(mesh.triangles[f][2]) + 1);
      EXPECT_GE(std::min({a, b, c}), 1);
      EXPECT_LE(std::max({a, b, c}), long(mesh.vertices.size()));
      ++f;
    } else {
      FAIL() << "unexpected OBJ line: " << line;
    }
  }
  EXPECT_EQ(v, mesh.vertices.size());
  EXPECT_EQ(f, mesh.triangles.size());
  EXPECT_GT(f, 0u);
  EXPECT_EQ(comments, 2u);
  EXPECT_TRUE(header_names_grid);
}

TEST_F(IsosurfaceTest, AdaptivityReducesTrianglesAndKeepsTheSurface) {
  const openvdb::FloatGrid::Ptr grid = makeSphere();
  TriangleMeshF full, adaptive;
  ASSERT_EQ(extractIsosurface(*grid, {0.0, 0.0}, &full), "");
  ASSERT_EQ(extractIsosurface(*grid, {0.0, 0.5}, &adaptive), "");
  EXPECT_LT(adaptive.triangles.size(), full.triangles.size());
  EXPECT_GT(signedVolume(adaptive), 0.95 * 4.0 / 3.0 * M_PI * kRadius * kRadius * kRadius);
}

TEST_F(IsosurfaceTest, InvalidDistancesAreErrors) {
  const openvdb::FloatGrid::Ptr grid = makeSphere();
  TriangleMeshF mesh;
  mesh.vertices.push_back({1, 2, 3});
  std::string err = extractIsosurface(*grid, {3.0, 0.0}, &mesh);
  EXPECT_NE(err.find("not inside the field's limit"), std::string::npos) << err;
  EXPECT_TRUE(mesh.vertices.empty());
  EXPECT_FALSE(extractIsosurface(*grid, {-3.5, 0.0}, &mesh).empty());
  err = extractIsosurface(*grid, {std::numeric_limits<double>::quiet_NaN(), 0.0}, &mesh);
  EXPECT_NE(err.find("finite"), std::string::npos) << err;
  err = extractIsosurface(*grid, {0.0, 1.5}, &mesh);
  EXPECT_NE(err.find("adaptivity"), std::string::npos) << err;
  const std::string path = (dir_ / "never.obj").string();
  EXPECT_FALSE(writeIsosurfaceObj(path, *grid, {5.0, 0.0}).empty());
  EXPECT_FALSE(fs::exists(path));
  // An unwritable destination is reported.
  err = writeIsosurfaceObj((dir_ / "missing" / "x.obj").string(), *grid, {0.0, 0.0});
  EXPECT_NE(err.find("temporary file"), std::string::npos) << err;
}

TEST_F(IsosurfaceTest, ADistanceThatMeetsNoVoxelsGivesAnEmptyMesh) {
  // A grid whose values are all positive (a surface seen only from outside the band) has no surface at 0.
  openvdb::FloatGrid grid(/*background=*/2.f);
  grid.tree().setValue(openvdb::Coord(0, 0, 0), 1.f);
  grid.tree().setValue(openvdb::Coord(1, 0, 0), 1.5f);
  TriangleMeshF mesh;
  ASSERT_EQ(extractIsosurface(grid, {0.0, 0.0}, &mesh), "");
  EXPECT_TRUE(mesh.vertices.empty());
  EXPECT_TRUE(mesh.triangles.empty());
  const std::string path = (dir_ / "empty.obj").string();
  ASSERT_EQ(writeObj(path, mesh), "");
  std::ifstream in(path);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all, "# 0 vertices, 0 triangles\n");
}

TEST(ObjWriterTest, RejectsOutOfRangeIndices) {
  TriangleMeshF mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 3}};
  const std::string err = writeObj((fs::temp_directory_path() / "distband_never.obj").string(), mesh);
  EXPECT_NE(err.find("vertex 3 of 3"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(fs::temp_directory_path() / "distband_never.obj"));
}

}  // namespace
}  // namespace distband
