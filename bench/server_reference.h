// ServerReference: the field a distband server must stream for a v1::QueryRequest, computed in this process by the
// server's own code path — the reference of every bench that talks to a server (service_bench, hostile_load,
// scale_out_bench).
// Contract:
//   * Assets: addMesh / addMeshFile / addVolume parse the same bytes a bench uploads with the server's own parsing
//     (server/asset_parsing.h) into a local AssetCache, under the id the server gives those bytes (so a request's
//     asset_id resolves here as it does there).
//   * resolve(): checkInlineMesh, the inline mesh's parse, then resolveQuery (server/request_validation.h) — grid,
//     padding, plan, limit, admission estimate — exactly as DistanceFieldService::runQuery calls them.
//   * run(): what QueryJob runs for a resolved query (server/query_job.cc): buildFieldInputs then computeField with
//     the plan's run options and the server's chunking; the caller picks the threads (the result is bit-identical for
//     any thread count). Whole-grid queries only (a tile request is refused: the benches compare whole fields).
//     Float32 encoding only: a FLOAT16 stream would need the codec's rounding.
//   * field(): resolve + run into a DeliveredField.
// Nothing here derives a grid, a padding, a sign or a stencil: change a default in core or the server and this
// follows. Thread-safe for concurrent resolve/run/field calls after the assets are added.
#pragma once

#include <string>
#include <string_view>

#include "bench/planned_field.h"
#include "distband/v1/distband.pb.h"
#include "server/asset_cache.h"
#include "server/request_validation.h"
#include "server/server_options.h"

namespace distband::bench {

class ServerReference {
 public:
  explicit ServerReference(ServerOptions options = {});

  /// `asset_id` (optional) gets the id the server gives these bytes.
  Status addMesh(std::string_view bytes, v1::MeshFormat format, const std::string& name, std::string* asset_id = nullptr);
  /// Reads `path` (format from its extension) and adds it.
  Status addMeshFile(const std::string& path, std::string* asset_id = nullptr);
  Status addVolume(const v1::Dims& dims, std::string bytes, const std::string& name, std::string* asset_id = nullptr);

  Status resolve(const v1::QueryRequest& request, ResolvedQuery* out);

  struct Run {
    FieldRunResult result;
    double inputs_seconds = 0;  ///< buildFieldInputs
    double total_seconds = 0;   ///< buildFieldInputs + computeField, callbacks included
  };
  Status run(const ResolvedQuery& query, int threads, const SegmentCallback& on_segment, Run* out) const;

  /// resolve + run, every delivered brick in `out` (on the resolved grid); `resolved` (optional) gets the query.
  Status field(const v1::QueryRequest& request, int threads, DeliveredField* out, ResolvedQuery* resolved = nullptr);

  const ServerOptions& options() const { return options_; }

 private:
  ServerOptions options_;
  AssetCache cache_;
};

}  // namespace distband::bench
