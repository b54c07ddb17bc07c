// Request validation: a distband.v1.QueryRequest checked field by field and resolved into what the engine needs.
// Contract: resolveQuery() never trusts the request. It answers INVALID_ARGUMENT (a field breaks a rule),
// NOT_FOUND (asset_id not in the cache) or RESOURCE_EXHAUSTED (voxel budget, message limits), with a message
// that names the field and the rule, e.g. "grid.resolution must be in [2, 16384] (got 1)". On OK, `out` holds
// the grid, the engine options (without an interrupter) and the seeds' source; building the Seeds themselves is
// compute work and happens later on the compute thread (server/seed_builder.h).
// Inline meshes are parsed here (on the calling thread); they are bounded by the message size limit.
// Thread-safe (the cache is).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <grpcpp/support/status.h>

#include "core/engine.h"
#include "core/grid.h"
#include "distband/v1/distband.pb.h"
#include "server/asset_cache.h"
#include "server/server_options.h"

namespace distband {

struct ResolvedQuery {
  enum class SeedKind { kPoints, kVolume, kMesh };
  SeedKind seed_kind = SeedKind::kPoints;
  std::vector<Vec3d> points;            ///< kPoints, world coordinates
  std::shared_ptr<const Asset> asset;   ///< kVolume / kMesh (cached or inline)
  std::string seeds_label;              ///< for logs, e.g. "points(2)" or "mesh-1a2b…(bunny.obj)"

  Grid grid;
  EngineOptions engine;                 ///< threads and interrupted are set by the job
  v1::SignMode sign = v1::SIGN_MODE_UNSIGNED;            ///< never UNSPECIFIED
  v1::Stencil stencil = v1::STENCIL_CUBIC26;             ///< never UNSPECIFIED
  v1::PropagationMode mode = v1::PROPAGATION_MODE_EXACT; ///< never UNSPECIFIED
  v1::BrickEncoding encoding = v1::BRICK_ENCODING_FLOAT32;  ///< never UNSPECIFIED
  uint32_t batch_bytes = 1u << 20;

  bool signedField() const { return sign != v1::SIGN_MODE_UNSIGNED; }
};

grpc::Status resolveQuery(const v1::QueryRequest& request, const ServerOptions& options, AssetCache& cache,
                          ResolvedQuery* out);

/// The header message describing a resolved query (first message of the stream).
void fillQueryHeader(const ResolvedQuery& query, const std::string& query_id, v1::QueryHeader* header);

}  // namespace distband
