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

std::string volumeAssetId(const v1::Dims& d, VoxelType type, std::string_view bytes) {
  // uint8 volumes keep the ids they always had.
  const std::string head = type == VoxelType::kUint8 ? fmt::format("{},{},{}:", d.x(), d.y(), d.z())
                                                     : fmt::format("{},{},{},{}:", d.x(), d.y(), d.z(), voxelTypeName(type));
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

uint64_t volumeParsePeakBytes(uint64_t bytes) { return bytes + bytes / 256 + (uint64_t(1) << 16); }

bool voxelTypeOf(v1::VoxelType type, VoxelType* out) {
  switch (type) {
    case v1::VOXEL_TYPE_UNSPECIFIED:
    case v1::VOXEL_TYPE_UINT8: *out = VoxelType::kUint8; return true;
    case v1::VOXEL_TYPE_UINT16: *out = VoxelType::kUint16; return true;
    case v1::VOXEL_TYPE_UINT32: *out = VoxelType::kUint32; return true;
    default: return false;
  }
}

v1::VoxelType v1VoxelType(VoxelType type) {
  switch (type) {
    case VoxelType::kUint16: return v1::VOXEL_TYPE_UINT16;
    case VoxelType::kUint32: return v1::VOXEL_TYPE_UINT32;
    case VoxelType::kUint8: break;
  }
  return v1::VOXEL_TYPE_UINT8;
}

Status parseVolumeAsset(const v1::Dims& dims, v1::VoxelType element_type, std::string bytes, const std::string& name,
                        std::string_view field, uint64_t max_voxels, const Interrupter* interrupter,
                        std::shared_ptr<const Asset>* out) {
  VoxelType type;
  if (!voxelTypeOf(element_type, &type))
    return Status::InvalidArgument(
        fmt::format("{}.element_type must be a VoxelType value 0..3 (got {})", field, int(element_type)));
  if (Status s = checkDims(dims, fmt::format("{}.dims", field)); !s.ok()) return s;
  const uint64_t voxels = uint64_t(dims.x()) * dims.y() * dims.z();
  if (voxels > max_voxels)
    return Status::ResourceExhausted(fmt::format("{}.dims: {}x{}x{} = {} voxels exceeds the server's voxel budget of {}",
                                                 field, dims.x(), dims.y(), dims.z(), voxels, max_voxels));
  const size_t width = voxelTypeBytes(type);
  if (bytes.size() != voxels * width)
    return Status::InvalidArgument(fmt::format(
        "{}: the volume has {} bytes but dims {}x{}x{} of {} need exactly {} ({} byte{} per voxel)", field,
        bytes.size(), dims.x(), dims.y(), dims.z(), voxelTypeName(type), voxels * width, width, width > 1 ? "s" : ""));
  const Coord d{int32_t(dims.x()), int32_t(dims.y()), int32_t(dims.z())};
  const std::string id = volumeAssetId(dims, type, bytes);
  LabelVolume volume(d, type, std::make_shared<const std::vector<uint8_t>>(bytes.begin(), bytes.end()));
  std::string().swap(bytes);
  auto footprint = std::make_shared<VolumeFootprint>();
  if (Status s = analyzeVolume(volume, interrupter, footprint.get()); !s.ok()) return s;
  if (footprint->seed_voxels == 0)
    return Status::InvalidArgument(fmt::format("{}: the mask has no nonzero (seed) voxel", field));
  auto asset = std::make_shared<Asset>();
  asset->kind = Asset::Kind::kVolume;
  asset->id = id;
  asset->name = name;
  asset->volume = std::move(volume);
  asset->footprint = std::move(footprint);
  *out = std::move(asset);
  return Status::Ok();
}

}  // namespace distband
