// Tests for core/mesh/ply_writer: the canonical binary PLY reads back as the same mesh, bit for bit.
#include "core/mesh/ply_writer.h"

#include <gtest/gtest.h>

#include "core/mesh/mesh_reader.h"

namespace distband {
namespace {

TEST(PlyWriterTest, ReadsBackAsTheSameMesh) {
  TriangleMesh mesh;
  mesh.vertices = {{0.1, 0.2, 0.3}, {1.0 / 3.0, -2.5e-7, 4.0}, {-1e6, 7.25, 0.0}, {2.0, 2.0, 2.0 + 1e-12}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {1, 3, 2}, {0, 3, 1}};
  const std::string bytes = encodeBinaryPly(mesh);
  TriangleMesh back;
  MeshReport report;
  ASSERT_TRUE(readMesh(bytes, MeshFormat::kPly, {}, nullptr, &back, &report).ok());
  EXPECT_EQ(back.vertices, mesh.vertices);
  EXPECT_EQ(back.triangles, mesh.triangles);
  EXPECT_EQ(report.boundary_edges, 0);
}

}  // namespace
}  // namespace distband
