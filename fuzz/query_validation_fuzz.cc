// Fuzz target: request validation (server/request_validation.h) on arbitrary bytes read as a QueryRequest, the way
// the server sees a hostile client's request. The cache holds a small mesh and a small volume so that asset ids
// resolve. Validation must never crash, and an accepted request must be within the server's limits (a tile's window
// within the grid and the budget).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "distband/v1/distband.pb.h"
#include "server/asset_parsing.h"
#include "server/request_validation.h"

namespace {

struct Fixture {
  distband::ServerOptions options;
  distband::AssetCache cache{uint64_t(64) << 20};
  Fixture() {
    options.max_voxels_per_query = uint64_t(1) << 22;  // keep accepted grids small: the estimate scans seeds
    std::shared_ptr<const distband::Asset> mesh, volume;
    const std::string tet = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    if (distband::parseMeshAsset(tet, distband::v1::MESH_FORMAT_OBJ, "tet", "mesh", {}, nullptr, &mesh).ok())
      cache.insert(mesh);
    distband::v1::Dims dims;
    dims.set_x(8), dims.set_y(8), dims.set_z(8);
    std::string mask(512, '\0');
    mask[100] = 1;
    if (distband::parseVolumeAsset(dims, distband::v1::VOXEL_TYPE_UINT8, mask, "vol", "volume", 1 << 20, nullptr, &volume).ok()) cache.insert(volume);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Fixture* f = new Fixture;
  distband::v1::QueryRequest request;
  if (!request.ParseFromArray(data, int(size))) return 0;
  if (!distband::checkInlineMesh(request, f->options).ok()) return 0;
  std::shared_ptr<const distband::Asset> inline_mesh;
  if (request.seeds_case() == distband::v1::QueryRequest::kMesh &&
      !distband::parseMeshAsset(request.mesh().data(), request.mesh().format(), "inline", "mesh",
                                distband::MeshLimits{1 << 12, 1 << 12}, nullptr, &inline_mesh)
           .ok())
    return 0;
  distband::ResolvedQuery q;
  if (!distband::resolveQuery(request, f->options, f->cache, inline_mesh, &q).ok()) return 0;
  // The budget bounds what is computed: the whole grid, or a tile's window.
  const distband::Grid computed = q.engineGrid();
  if (uint64_t(computed.voxelCount()) > f->options.max_voxels_per_query) __builtin_trap();
  if (!q.grid.validate().ok() || !computed.validate().ok()) __builtin_trap();
  if (q.touched_voxels_bound > uint64_t(computed.voxelCount())) __builtin_trap();
  if (q.tile) {
    const distband::VoxelBox whole{{}, q.grid.dims()};
    if (!whole.contains(q.tile->window) || !q.tile->window.contains(q.tile->deliver)) __builtin_trap();
    if (q.tile->window.min.x % 8 || q.tile->window.min.y % 8 || q.tile->window.min.z % 8) __builtin_trap();
  }
  distband::v1::QueryHeader header;
  distband::fillQueryHeader(q, "q", &header);
  return 0;
}
