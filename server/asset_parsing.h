// Asset parsing: turns uploaded (or inline) bytes into validated, immutable Assets, in memory.
// Contract: every failure is a Status — kInvalidArgument (the bytes break a rule of their format), kResourceExhausted
// (a server limit: --max-triangles, --max-vertices, --max-voxels) or the interrupter's status — whose message starts
// with `field` (the request field the bytes came from) and states the rule, never quoting more than a short escaped
// excerpt of the bytes and never naming a server path. Parsing never touches the file system. Long work polls
// `interrupter`. Thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "core/interrupter.h"
#include "core/status.h"
#include "distband/v1/distband.pb.h"
#include "server/asset_cache.h"

namespace distband {

/// "obj", "off", "ply", "stl", or "" for UNSPECIFIED / unknown values.
std::string_view meshFormatExtension(v1::MeshFormat format);

/// OK when 1 <= each extent <= kMaxGridDim, otherwise "<field>.x must be in [1, 16384] (got 0)" etc.
Status checkDims(const v1::Dims& dims, std::string_view field);

struct MeshLimits {
  uint64_t max_vertices = uint64_t(1) << 24;
  uint64_t max_triangles = uint64_t(1) << 24;
};

/// Upper bound on the bytes parseMeshAsset allocates for `input_bytes` of mesh data, the data itself excluded (the
/// parse is admitted with it; core/mesh/mesh_reader.h measures it).
uint64_t meshParsePeakBytes(uint64_t input_bytes);

Status parseMeshAsset(std::string_view bytes, v1::MeshFormat format, const std::string& name, std::string_view field,
                      const MeshLimits& limits, const Interrupter* interrupter, std::shared_ptr<const Asset>* out);

/// The element type a request names (kUint8 for UNSPECIFIED); false for an unknown value. v1VoxelType: the inverse.
bool voxelTypeOf(v1::VoxelType type, VoxelType* out);
v1::VoxelType v1VoxelType(VoxelType type);

/// `max_voxels` bounds dims.x*dims.y*dims.z (kResourceExhausted beyond it). `bytes` is taken over.
Status parseVolumeAsset(const v1::Dims& dims, v1::VoxelType type, std::string bytes, const std::string& name,
                        std::string_view field, uint64_t max_voxels, const Interrupter* interrupter,
                        std::shared_ptr<const Asset>* out);

/// Peak bytes parseVolumeAsset allocates for `bytes` of volume data, the data itself excluded (the volume's copy
/// and the brick footprint).
uint64_t volumeParsePeakBytes(uint64_t bytes);

/// The cache id parseMeshAsset / parseVolumeAsset would give these bytes (so uploads can hit the cache first).
std::string meshAssetId(std::string_view bytes, v1::MeshFormat format);
std::string volumeAssetId(const v1::Dims& dims, VoxelType type, std::string_view bytes);

}  // namespace distband
