// DistanceFieldService: the distband.v1.DistanceField gRPC service (synchronous API).
// Contract:
//   * gRPC handler threads only validate, wait for the bounded queue and write; compute happens on each query's
//     own compute thread inside the shared TBB arena (server/query_job.h).
//   * At most options.max_concurrent_queries queries compute at once; a query beyond that waits up to
//     options.queue_wait_ms, then gets RESOURCE_EXHAUSTED.
//   * Client cancel, disconnect, deadline and server shutdown stop the query's engine within one engine step
//     plus the handler's 5 ms poll, and its queued messages are dropped at once.
//   * beginShutdown() makes new queries and uploads fail with UNAVAILABLE; running ones continue.
//   * Every request ends with one spdlog line (method, peer, outcome, sizes, timings).
// Thread-safe.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include <tbb/task_arena.h>

#include "distband/v1/distband.grpc.pb.h"
#include "server/asset_cache.h"
#include "server/query_slots.h"
#include "server/server_options.h"

namespace distband {

class DistanceFieldService final : public v1::DistanceField::Service {
 public:
  DistanceFieldService(const ServerOptions& options, ServerHooks hooks);
  ~DistanceFieldService() override;

  grpc::Status UploadMesh(grpc::ServerContext* context, grpc::ServerReader<v1::UploadMeshChunk>* reader,
                          v1::UploadReply* reply) override;
  grpc::Status UploadVolume(grpc::ServerContext* context, grpc::ServerReader<v1::UploadVolumeChunk>* reader,
                            v1::UploadReply* reply) override;
  grpc::Status Query(grpc::ServerContext* context, const v1::QueryRequest* request,
                     grpc::ServerWriter<v1::QueryReply>* writer) override;
  grpc::Status GetInfo(grpc::ServerContext* context, const v1::GetInfoRequest* request,
                       v1::ServerInfo* reply) override;

  void beginShutdown() { shutting_down_.store(true); }
  int activeQueries() const { return slots_.active(); }
  AssetCache& cache() { return cache_; }

 private:
  template <typename Chunk>
  grpc::Status readUpload(grpc::ServerContext* context, grpc::ServerReader<Chunk>* reader, std::string* data,
                          Chunk* first, const char* what);
  grpc::Status runQuery(grpc::ServerContext* context, const v1::QueryRequest& request,
                        grpc::ServerWriter<v1::QueryReply>* writer, QueryRecord* record);

  const ServerOptions options_;
  const ServerHooks hooks_;
  std::unique_ptr<tbb::task_arena> arena_;
  AssetCache cache_;
  QuerySlots slots_;
  std::atomic<bool> shutting_down_{false};
  std::atomic<uint64_t> next_query_{1};
};

}  // namespace distband
