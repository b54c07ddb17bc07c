// openvdb_mesh_process: the OpenVDB peer of `distband compute --mesh` as a whole process, for whole_process_bench.
// It does the same job a user of OpenVDB would write for it:
//   read the mesh file -> openvdb::tools::meshToSignedDistanceField -> write the .vdb with openvdb::io::File.
// Contract:
//   * The mesh is read with distband's own reader (core/mesh: loadMesh — a strict from_chars parser of the whole
//     file held in memory, then weld/validate), so both processes pay the same parse; OpenVDB ships no mesh reader,
//     and this one is at least as fast as what a user would typically write with iostreams.
//   * The grid is given, not derived: --voxel-size H --origin X,Y,Z --dims NX,NY,NZ are the grid `distband compute`
//     planned for the same job (whole_process_bench reads them from distband's --meta output), so both fields share
//     one lattice; the transform is voxel size H translated to the origin (voxel (i,j,k) at origin + H*(i,j,k)), and
//     the dims are stored as the grid's "distband_dims" metadata, as distband's writer stores them (OpenVDB's grid is
//     sparse: it does not clip to them). The narrow band is --half-width W voxels (the limit distband planned, in
//     voxels) on both sides (exBandWidth = inBandWidth = W).
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

#include "core/mesh/triangle_mesh.h"

namespace {

int fail(const std::string& message) {
  std::fprintf(stderr, "openvdb_mesh_process: %s\n", message.c_str());
  return 1;
}

bool parseTriple(const std::string& text, double out[3]) {
  return std::sscanf(text.c_str(), "%lf,%lf,%lf", &out[0], &out[1], &out[2]) == 3;
}

}  // namespace

int main(int argc, char** argv) {
  std::string mesh_path, out_path;
  double voxel_size = 0, half_width = 0, origin[3] = {0, 0, 0}, dims[3] = {0, 0, 0};
  bool have_origin = false, have_dims = false;
  int threads = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--mesh") mesh_path = value;
    else if (flag == "--out") out_path = value;
    else if (flag == "--voxel-size") voxel_size = std::strtod(value.c_str(), nullptr);
    else if (flag == "--origin") have_origin = parseTriple(value, origin);
    else if (flag == "--dims") have_dims = parseTriple(value, dims);
    else if (flag == "--half-width") half_width = std::strtod(value.c_str(), nullptr);
    else if (flag == "--threads") threads = std::atoi(value.c_str());
    else
      return fail("unknown flag " + flag +
                  " (expected --mesh --out --voxel-size --origin X,Y,Z --dims NX,NY,NZ --half-width --threads)");
  }
  if (mesh_path.empty() || out_path.empty()) return fail("give --mesh FILE and --out FILE.vdb");
  if (!(voxel_size > 0) || !have_origin || !have_dims || !(half_width > 0))
    return fail("give the planned grid: --voxel-size H > 0, --origin X,Y,Z, --dims NX,NY,NZ and --half-width W > 0");
  std::unique_ptr<tbb::global_control> parallelism;
  if (threads > 0)
    parallelism = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);

  distband::TriangleMesh mesh;
  distband::MeshReport report;
  if (distband::Status e = distband::loadMesh(mesh_path, &mesh, &report); !e.ok()) return fail(e.toString());

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  points.reserve(mesh.vertices.size());
  triangles.reserve(mesh.triangles.size());
  for (const distband::Vec3d& v : mesh.vertices) points.emplace_back(float(v.x), float(v.y), float(v.z));
  for (const auto& t : mesh.triangles) triangles.emplace_back(t[0], t[1], t[2]);

  openvdb::initialize();
  auto transform = openvdb::math::Transform::createLinearTransform(voxel_size);
  transform->postTranslate(openvdb::Vec3d(origin[0], origin[1], origin[2]));
  auto sdf = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(*transform, points, triangles, quads,
                                                                           float(half_width), float(half_width));
  // meshToVolume keeps a copy of the transform, and copying a UniformScaleTranslateMap recomputes its scale (an ulp
  // off): the file gets the transform this job was given.
  sdf->setTransform(transform);
  sdf->setName("distance");
  sdf->setGridClass(openvdb::GRID_LEVEL_SET);
  sdf->insertMeta("distband_dims", openvdb::Vec3IMetadata(openvdb::Vec3i(int(dims[0]), int(dims[1]), int(dims[2]))));
  try {
    openvdb::io::File file(out_path);
    file.write({sdf});
    file.close();
  } catch (const std::exception& e) {
    return fail(out_path + ": " + e.what());
  }
  return 0;
}
