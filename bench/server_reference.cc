#include "bench/server_reference.h"

#include <chrono>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "client/remote_client.h"
#include "core/field/compute_field.h"
#include "server/asset_parsing.h"

namespace distband::bench {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// The cache holds whatever a bench adds: its capacity is no figure of the server's.
ServerReference::ServerReference(ServerOptions options) : options_(std::move(options)), cache_(uint64_t(64) << 30) {}

Status ServerReference::addMesh(std::string_view bytes, v1::MeshFormat format, const std::string& name,
                                std::string* asset_id) {
  std::shared_ptr<const Asset> asset;
  const MeshLimits limits{options_.max_vertices, options_.max_triangles};
  if (Status s = parseMeshAsset(bytes, format, name, "UploadMeshChunk.data", limits, nullptr, &asset); !s.ok())
    return s;
  if (asset_id) *asset_id = asset->id;
  if (!cache_.insert(asset)) return Status::ResourceExhausted("the reference's asset cache is full");
  return Status::Ok();
}

Status ServerReference::addMeshFile(const std::string& path, std::string* asset_id) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::IoError(path + ": cannot be read");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return addMesh(bytes.str(), meshFormatFromPath(path), path, asset_id);
}

Status ServerReference::addVolume(const v1::Dims& dims, std::string bytes, const std::string& name,
                                  std::string* asset_id) {
  std::shared_ptr<const Asset> asset;
  if (Status s = parseVolumeAsset(dims, v1::VOXEL_TYPE_UINT8, std::move(bytes), name, "UploadVolumeChunk.header", options_.max_voxels_per_query,
                                  nullptr, &asset);
      !s.ok())
    return s;
  if (asset_id) *asset_id = asset->id;
  if (!cache_.insert(asset)) return Status::ResourceExhausted("the reference's asset cache is full");
  return Status::Ok();
}

Status ServerReference::resolve(const v1::QueryRequest& request, ResolvedQuery* out) {
  if (Status s = checkInlineMesh(request, options_); !s.ok()) return s;
  std::shared_ptr<const Asset> inline_mesh;
  if (request.seeds_case() == v1::QueryRequest::kMesh) {
    const MeshLimits limits{options_.max_vertices, options_.max_triangles};
    if (Status s = parseMeshAsset(request.mesh().data(), request.mesh().format(), "inline mesh", "mesh", limits,
                                  nullptr, &inline_mesh);
        !s.ok())
      return s;
  }
  return resolveQuery(request, options_, cache_, std::move(inline_mesh), out);
}

Status ServerReference::run(const ResolvedQuery& q, int threads, const SegmentCallback& on_segment, Run* out) const {
  if (q.tile) return Status::InvalidArgument("ServerReference: tile requests are not supported (compare whole fields)");
  if (q.encoding != v1::BRICK_ENCODING_FLOAT32)
    return Status::InvalidArgument("ServerReference: only BRICK_ENCODING_FLOAT32 streams are compared");
  Run r;
  const auto t0 = std::chrono::steady_clock::now();
  SeedSource source;
  source.points = &q.points;
  if (q.asset) {
    source.volume = q.asset->volume;
    source.mesh = q.asset->mesh.get();
  }
  FieldInputs inputs;
  if (Status s = buildFieldInputs(q.plan, q.grid, nullptr, source, nullptr, &inputs); !s.ok())
    return s.withPrefix("seeds");
  r.inputs_seconds = secondsSince(t0);
  FieldRunOptions options = q.plan.runOptions();
  options.threads = threads;
  options.max_chunk_bricks = kQueryChunkBricks;
  r.result = computeField(q.plan, q.engineGrid(), std::move(inputs), options, on_segment);
  r.total_seconds = secondsSince(t0);
  *out = std::move(r);
  return Status::Ok();
}

Status ServerReference::field(const v1::QueryRequest& request, int threads, DeliveredField* out,
                              ResolvedQuery* resolved) {
  ResolvedQuery q;
  if (Status s = resolve(request, &q); !s.ok()) return s;
  DeliveredField field(q.grid);
  Run run;
  if (Status s = this->run(q, threads, [&](SegmentBricks&& b) { field.add(b); }, &run); !s.ok()) return s;
  *out = std::move(field);
  if (resolved) *resolved = std::move(q);
  return Status::Ok();
}

}  // namespace distband::bench
