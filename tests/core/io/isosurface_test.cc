// Tests for core/io/isosurface: isosurfaces of an exact sphere level set (a VdbFieldBuilder of its bricks) at
// distances 0 and 2 — vertex radii, orientation (outward), closedness, the same mesh at any thread count, and the OBJ
// file parsed back; invalid distances are errors.
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

#include <memory>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "core/io/vdb_writer.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

constexpr float kRadius = 10.f;
constexpr float kVoxel = 0.25f;
struct Centre {
  float x() const { return 1.f; }
  float y() const { return -2.f; }
  float z() const { return 3.f; }
} const kCentre;

// The exact signed distance to the sphere, delivered within half width 12 voxels = 3 world units (so the band holds
// the surfaces at distance 0 and 2), flood-filled.
std::unique_ptr<VdbFieldBuilder> makeSphere() {
  const Grid grid({kCentre.x() - 14.0, kCentre.y() - 14.0, kCentre.z() - 14.0}, kVoxel, {120, 120, 120});
  auto builder = std::make_unique<VdbFieldBuilder>(grid, 3.f);
  for (int bz = 0; bz < 120; bz += 8)
    for (int by = 0; by < 120; by += 8)
      for (int bx = 0; bx < 120; bx += 8) {
        Brick b;
        b.origin = {bx, by, bz};
        for (int i = 0; i < kBrickVoxels; ++i) {
          const Vec3d w = grid.worldOf(b.origin + brickLocal(i));
          const double d = std::sqrt((w.x - kCentre.x()) * (w.x - kCentre.x()) + (w.y - kCentre.y()) * (w.y - kCentre.y()) +
                                     (w.z - kCentre.z()) * (w.z - kCentre.z())) - kRadius;
          if (std::abs(d) >= 3.0) continue;
          b.mask.set(i);
          b.values[size_t(i)] = float(d);
        }
        builder->add(b);
      }
  builder->finish();
  return builder;
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
    dir_ = fs::temp_directory_path() / ("distband_isosurface_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(IsosurfaceTest, SphereSurfacesAtDistanceZeroAndTwo) {
  const auto sphere = makeSphere();
  ASSERT_NEAR(sphere->distance().background(), 3.f, 1e-6);
  for (const double d : {0.0, 2.0}) {
    SCOPED_TRACE(testing::Message() << "distance " << d);
    TriangleMeshF mesh;
    ASSERT_TRUE(IsOk(extractIsosurface(sphere->distance(), sphere->grid(), {d}, &mesh)));
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

TEST_F(IsosurfaceTest, TheMeshIsTheSameAtAnyThreadCount) {
  const auto sphere = makeSphere();
  TriangleMeshF one, two;
  {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, 1);
    ASSERT_TRUE(IsOk(extractIsosurface(sphere->distance(), sphere->grid(), {0.5}, &one)));
  }
  {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, 2);
    ASSERT_TRUE(IsOk(extractIsosurface(sphere->distance(), sphere->grid(), {0.5}, &two)));
  }
  EXPECT_EQ(one.vertices, two.vertices);
  EXPECT_EQ(one.triangles, two.triangles);
}

TEST_F(IsosurfaceTest, ObjFileParsesBackToTheMesh) {
  const auto sphere = makeSphere();
  const std::string path = (dir_ / "sphere_2.obj").string();
  TriangleMeshF mesh;
  IsosurfaceOptions options;
  options.distance_world = 2.0;
  options.field_name = "sphere";
  ASSERT_TRUE(IsOk(writeIsosurfaceObj(path, sphere->distance(), sphere->grid(), options, &mesh)));
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

TEST_F(IsosurfaceTest, InvalidDistancesAreErrors) {
  const auto sphere = makeSphere();
  const VdbTree<float>& field = sphere->distance();
  const Grid& grid = sphere->grid();
  TriangleMeshF mesh;
  mesh.vertices.push_back({1, 2, 3});
  constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;
  EXPECT_TRUE(IsError(extractIsosurface(field, grid, {3.0}, &mesh), kInvalid, "not inside the field's limit"));
  EXPECT_TRUE(mesh.vertices.empty());
  EXPECT_TRUE(IsError(extractIsosurface(field, grid, {-3.5}, &mesh), kInvalid,
                      "distance -3.5 is not inside the field's limit"));
  EXPECT_TRUE(IsError(extractIsosurface(field, grid, {std::numeric_limits<double>::quiet_NaN()}, &mesh), kInvalid,
                      "isosurface distance must be finite"));
  const std::string path = (dir_ / "never.obj").string();
  EXPECT_TRUE(IsError(writeIsosurfaceObj(path, field, grid, {5.0}), kInvalid, "not inside the field's limit"));
  EXPECT_FALSE(fs::exists(path));
  // An unfinished field is refused, not read half-built.
  VdbFieldBuilder unfinished(grid, 3.f);
  EXPECT_TRUE(IsError(extractIsosurface(unfinished.distance(), grid, {0.0}, &mesh), kInvalid,
                      "the field is not finished (sealed)"));
  // An unwritable destination is the OS refusing the file: an I/O error naming it.
  const std::string unwritable = (dir_ / "missing" / "x.obj").string();
  EXPECT_TRUE(IsError(writeIsosurfaceObj(unwritable, field, grid, {0.0}), Status::Code::kIoError,
                      "cannot create a temporary file next to '" + unwritable + "'"));
}

TEST_F(IsosurfaceTest, ADistanceThatMeetsNoVoxelsGivesAnEmptyMesh) {
  // A grid whose values are all positive (a surface seen only from outside the band) has no surface at 0.
  const Grid grid({0, 0, 0}, 1.0, {8, 8, 8});
  VdbFieldBuilder field(grid, 2.f);
  Brick b;
  b.mask.set(brickOffset(0, 0, 0));
  b.values[size_t(brickOffset(0, 0, 0))] = 1.f;
  b.mask.set(brickOffset(1, 0, 0));
  b.values[size_t(brickOffset(1, 0, 0))] = 1.5f;
  field.add(b);
  field.finish();
  TriangleMeshF mesh;
  ASSERT_TRUE(IsOk(extractIsosurface(field.distance(), grid, {0.0}, &mesh)));
  EXPECT_TRUE(mesh.vertices.empty());
  EXPECT_TRUE(mesh.triangles.empty());
  const std::string path = (dir_ / "empty.obj").string();
  ASSERT_TRUE(IsOk(writeObj(path, mesh)));
  std::ifstream in(path);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all, "# 0 vertices, 0 triangles\n");
}

TEST(ObjWriterTest, RejectsOutOfRangeIndices) {
  TriangleMeshF mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 3}};
  EXPECT_TRUE(IsError(writeObj((fs::temp_directory_path() / "distband_never.obj").string(), mesh),
                      Status::Code::kInvalidArgument, "OBJ: triangle refers to vertex 3 of 3"));
  EXPECT_FALSE(fs::exists(fs::temp_directory_path() / "distband_never.obj"));
}

}  // namespace
}  // namespace distband
