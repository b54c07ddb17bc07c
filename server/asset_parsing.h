// Asset parsing: turns uploaded (or inline) bytes into validated, immutable Assets.
// Contract: every failure is a grpc::Status (INVALID_ARGUMENT, or RESOURCE_EXHAUSTED for size limits) whose
// message starts with `field` (the request field the bytes came from) and states the rule that was broken;
// untrusted bytes never crash the server. Meshes are parsed by core's loadMesh (assimp) through a private
// temporary file, so every format core accepts is accepted here. Thread-safe.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include <grpcpp/support/status.h>

#include "distband/v1/distband.pb.h"
#include "server/asset_cache.h"

namespace distband {

/// "obj", "off", "ply", "stl", or "" for UNSPECIFIED / unknown values.
std::string_view meshFormatExtension(v1::MeshFormat format);

/// "" when 1 <= each extent <= kMaxGridDim, otherwise "<field>.x must be in [1, 16384] (got 0)" etc.
std::string checkDims(const v1::Dims& dims, std::string_view field);

grpc::Status parseMeshAsset(std::string_view bytes, v1::MeshFormat format, const std::string& name,
                            std::string_view field, std::shared_ptr<const Asset>* out);

/// `max_voxels` bounds dims.x*dims.y*dims.z (RESOURCE_EXHAUSTED beyond it).
grpc::Status parseVolumeAsset(const v1::Dims& dims, std::string bytes, const std::string& name,
                              std::string_view field, uint64_t max_voxels, std::shared_ptr<const Asset>* out);

/// The cache id parseMeshAsset / parseVolumeAsset would give these bytes (so uploads can hit the cache first).
std::string meshAssetId(std::string_view bytes, v1::MeshFormat format);
std::string volumeAssetId(const v1::Dims& dims, std::string_view bytes);

}  // namespace distband
