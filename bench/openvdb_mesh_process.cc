// openvdb_mesh_process: the OpenVDB peer of `distband compute --mesh` as a whole process, for whole_process_bench.
// It does the same job a user of OpenVDB would write for it:
//   read the mesh file -> openvdb::tools::meshToSignedDistanceField -> write the .vdb with openvdb::io::File.
// Contract:
//   * The mesh is read with distband's own reader (core/mesh: loadMesh — a strict from_chars parser of the whole
//     file held in memory, then weld/validate), so both processes pay the same parse; OpenVDB ships no mesh reader,
//     and this one is at least as fast as what a user would typically write with iostreams.
//   * The grid (voxel size and origin, so the transform) is core's gridForMesh with the same options
//     `distband compute --resolution N --limit-voxels W` uses, so both fields share one lattice; the narrow band is W
//     voxels on both sides (exBandWidth = inBandWidth = W).
//   * Threads: tbb::global_control(max_allowed_parallelism, --threads) (0: all cores), like distband's --threads.
//   * The file holds one FloatGrid named "distance", class GRID_LEVEL_SET, written with io::File's default
//     compression (the same writer defaults distband's VdbFieldBuilder uses).
//   * Prints nothing on success; exit status 0, or 1 with a message on stderr.
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/global_control.h>

#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"

namespace {

int fail(const std::string& message) {
  std::fprintf(stderr, "openvdb_mesh_process: %s\n", message.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string mesh_path, out_path;
  int resolution = 256, half_width = 3, threads = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--mesh") mesh_path = value;
    else if (flag == "--out") out_path = value;
    else if (flag == "--resolution") resolution = std::atoi(value.c_str());
    else if (flag == "--half-width") half_width = std::atoi(value.c_str());
    else if (flag == "--threads") threads = std::atoi(value.c_str());
    else return fail("unknown flag " + flag + " (expected --mesh --out --resolution --half-width --threads)");
  }
  if (mesh_path.empty() || out_path.empty()) return fail("give --mesh FILE and --out FILE.vdb");
  std::unique_ptr<tbb::global_control> parallelism;
  if (threads > 0)
    parallelism = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);

  distband::TriangleMesh mesh;
  distband::MeshReport report;
  if (distband::Status e = distband::loadMesh(mesh_path, &mesh, &report); !e.ok()) return fail(e.toString());
  distband::MeshGridOptions go;
  go.resolution = resolution;
  distband::Grid grid;
  if (distband::Status e =
          distband::gridForMesh(mesh, go, {std::numeric_limits<double>::infinity(), double(half_width)}, &grid);
      !e.ok())
    return fail(e.toString());

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  points.reserve(mesh.vertices.size());
  triangles.reserve(mesh.triangles.size());
  for (const distband::Vec3d& v : mesh.vertices) points.emplace_back(float(v.x), float(v.y), float(v.z));
  for (const auto& t : mesh.triangles) triangles.emplace_back(t[0], t[1], t[2]);

  openvdb::initialize();
  auto transform = openvdb::math::Transform::createLinearTransform(grid.voxelSize());
  transform->postTranslate(openvdb::Vec3d(grid.origin().x, grid.origin().y, grid.origin().z));
  auto sdf = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(*transform, points, triangles, quads,
                                                                           float(half_width), float(half_width));
  sdf->setName("distance");
  sdf->setGridClass(openvdb::GRID_LEVEL_SET);
  try {
    openvdb::io::File file(out_path);
    file.write({sdf});
    file.close();
  } catch (const std::exception& e) {
    return fail(out_path + ": " + e.what());
  }
  return 0;
}
