#include "server/asset_parsing.h"

#include <algorithm>

#include <fmt/format.h>

#include "core/grid.h"
#include "core/mesh/mesh_reader.h"

namespace distband {

std::string_view meshFormatExtension(v1::MeshFormat format) {
  switch (format) {
    case v1::MESH_FORMAT_OBJ: return "obj";
    case v1::MESH_FORMAT_OFF: return "off";
    case v1::MESH_FORMAT_PLY: return "ply";
    case v1::MESH_FORMAT_STL: return "stl";
    default: return "";
  }
}

Status checkDims(const v1::Dims& d, std::string_view field) {
  for (auto [axis, v] : {std::pair{"x", d.x()}, {"y", d.y()}, {"z", d.z()}})
    if (v < 1 || v > uint32_t(kMaxGridDim))
      return Status::InvalidArgument(fmt::format("{}.{} must be in [1, {}] (got {})", field, axis, kMaxGridDim, v));
  return Status::Ok();
}

std::string meshAssetId(std::string_view bytes, v1::MeshFormat format) {
  return "mesh-" + sha256Hex({meshFormatExtension(format), ":", bytes});
}

std::string volumeAssetId(const v1::Dims& d, std::string_view bytes) {
  const std::string head = fmt::format("{},{},{}:", d.x(), d.y(), d.z());
  return "volume-" + sha256Hex({head, bytes});
}

uint64_t meshParsePeakBytes(uint64_t input_bytes) { return meshReadPeakBytes(input_bytes); }

Status parseMeshAsset(std::string_view bytes, v1::MeshFormat format, const std::string& name, std::string_view field,
                      const MeshLimits& limits, const Interrupter* interrupter, std::shared_ptr<const Asset>* out) {
  const std::string_view ext = meshFormatExtension(format);
  if (ext.empty())
    return Status::InvalidArgument(
        fmt::format("{}.format must be one of MESH_FORMAT_OBJ, _OFF, _PLY, _STL (got {})", field, int(format)));
  if (bytes.empty()) return Status::InvalidArgument(fmt::format("{}: the mesh data is empty", field));
  MeshFormat parsed_format;
  switch (format) {
    case v1::MESH_FORMAT_OBJ: parsed_format = MeshFormat::kObj; break;
    case v1::MESH_FORMAT_OFF: parsed_format = MeshFormat::kOff; break;
    case v1::MESH_FORMAT_PLY: parsed_format = MeshFormat::kPly; break;
    default: parsed_format = MeshFormat::kStl; break;
  }
  auto asset = std::make_shared<Asset>();
  auto mesh = std::make_shared<TriangleMesh>();
  const MeshReadLimits read_limits{limits.max_vertices, limits.max_triangles};
  if (Status s = readMesh(bytes, parsed_format, read_limits, interrupter, mesh.get(), &asset->mesh_report); !s.ok())
    return s.withPrefix(field);
  asset->kind = Asset::Kind::kMesh;
  asset->id = meshAssetId(bytes, format);
  asset->name = name;
  asset->mesh = std::move(mesh);
  *out = std::move(asset);
  return Status::Ok();
}

uint64_t volumeParsePeakBytes(uint64_t voxels) { return voxels + voxels / 256 + (uint64_t(1) << 16); }

Status parseVolumeAsset(const v1::Dims& dims, std::string bytes, const std::string& name, std::string_view field,
                        uint64_t max_voxels, const Interrupter* interrupter, std::shared_ptr<const Asset>* out) {
  if (Status s = checkDims(dims, fmt::format("{}.dims", field)); !s.ok()) return s;
  const uint64_t voxels = uint64_t(dims.x()) * dims.y() * dims.z();
  if (voxels > max_voxels)
    return Status::ResourceExhausted(fmt::format("{}.dims: {}x{}x{} = {} voxels exceeds the server's voxel budget of {}",
                                                 field, dims.x(), dims.y(), dims.z(), voxels, max_voxels));
  if (bytes.size() != voxels)
    return Status::InvalidArgument(
        fmt::format("{}: the mask has {} bytes but dims {}x{}x{} need exactly {} (one byte per voxel)", field,
                    bytes.size(), dims.x(), dims.y(), dims.z(), voxels));
  const Coord d{int32_t(dims.x()), int32_t(dims.y()), int32_t(dims.z())};
  auto footprint = std::make_shared<VolumeFootprint>();
  if (Status s = analyzeVolume(d, reinterpret_cast<const uint8_t*>(bytes.data()), interrupter, footprint.get());
      !s.ok())
    return s;
  if (footprint->seed_voxels == 0)
    return Status::InvalidArgument(fmt::format("{}: the mask has no nonzero (seed) voxel", field));
  auto asset = std::make_shared<Asset>();
  asset->kind = Asset::Kind::kVolume;
  asset->id = volumeAssetId(dims, bytes);
  asset->name = name;
  asset->dims = d;
  asset->mask = std::make_shared<const std::vector<uint8_t>>(bytes.begin(), bytes.end());
  asset->footprint = std::move(footprint);
  *out = std::move(asset);
  return Status::Ok();
}

}  // namespace distband
