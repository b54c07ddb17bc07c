// DistanceFieldService: the distband.v1.DistanceField gRPC service (synchronous API), hardened for untrusted
// clients.
// Contract, for every call:
//   1. Admission of the call itself (server/active_calls.h): at most --max-streams in flight, else
//      RESOURCE_EXHAUSTED at once; a token check when --auth-token-file is set (UNAUTHENTICATED); UNAVAILABLE once
//      shutdown has begun. The call gets one Interrupter (client deadline, cancel, idle watchdog, shutdown) that every
//      phase polls.
//   2. Validation before any work (server/request_validation.h): every rule of the .proto, cheap.
//   3. Admission of the work: an estimate of its peak bytes is reserved in the memory budget
//      (server/memory_budget.h) and a compute slot is taken (at most --max-queries computing, uploads' parsing
//      included); both wait at most --queue-wait-ms, then RESOURCE_EXHAUSTED saying what was asked and what is free.
//   4. Compute on a dedicated thread inside the shared TBB arena (never on a gRPC thread's stack budget), while the
//      handler thread polls its context every 5 ms so a client cancel trips the Interrupter at once.
//   * Uploads: the declared total_bytes is checked on the first chunk; the buffer grows only as bytes arrive and
//     only as far as the memory budget allows; parsing happens in memory (no file is ever opened because of what
//     a mesh says) under the same admission as queries.
//   * Errors are core Status values mapped to gRPC codes in one place (server/grpc_status.h).
//   * beginShutdown(): new calls get UNAVAILABLE; stopAll() cancels the running ones (end of the grace period).
//   * Every call has a request id (server/request_id.h: the client's x-request-id or a generated one), echoed in its
//     initial metadata, passed to replicas, and in every log line of the call.
//   * Every call ends with one log line (server/log_line.h: method, request id, peer, outcome, sizes, timings) and
//     its reports to Metrics (server/metrics.h: the call by code and its duration; a query's admission wait, first
//     brick, seed and compute time, voxels and bytes sent; an upload's bytes, parse time and refusal reason).
//     Gauges of the service's state (streams, budget, cache, replicas) are read at scrape time.
// Thread-safe.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <tbb/task_arena.h>

#include "distband/v1/distband.grpc.pb.h"
#include "server/active_calls.h"
#include "server/asset_cache.h"
#include "server/memory_budget.h"
#include "server/metrics.h"
#include "server/query_slots.h"
#include "server/replica_pool.h"
#include "server/request_id.h"
#include "server/server_options.h"
#include "server/token_auth.h"

namespace distband {

/// How the server's --memory-budget is divided (see ServerOptions::memory_budget_bytes).
struct MemoryPlan {
  uint64_t total = 0;     ///< --memory-budget
  uint64_t baseline = 0;  ///< the process itself: code, libraries, thread stacks, TBB
  uint64_t cache = 0;     ///< the asset cache's capacity
  uint64_t grpc = 0;      ///< gRPC's resource quota (its transport buffers)
  uint64_t requests = 0;  ///< what uploads and queries are admitted against
  static MemoryPlan of(const ServerOptions& options);
};

class DistanceFieldService final : public v1::DistanceField::Service {
 public:
  /// `auth` may be null (no token required). `metrics` (disabled or not) must outlive the service.
  DistanceFieldService(const ServerOptions& options, ServerHooks hooks, std::unique_ptr<TokenAuth> auth,
                       Metrics& metrics);
  ~DistanceFieldService() override;

  grpc::Status UploadMesh(grpc::ServerContext* context, grpc::ServerReader<v1::UploadMeshChunk>* reader,
                          v1::UploadReply* reply) override;
  grpc::Status UploadVolume(grpc::ServerContext* context, grpc::ServerReader<v1::UploadVolumeChunk>* reader,
                            v1::UploadReply* reply) override;
  grpc::Status Query(grpc::ServerContext* context, const v1::QueryRequest* request,
                     grpc::ServerWriter<v1::QueryReply>* writer) override;
  grpc::Status GetInfo(grpc::ServerContext* context, const v1::GetInfoRequest* request,
                       v1::ServerInfo* reply) override;
  /// Distances at points (see QueryPoints in the .proto): the header is validated before any work, the search is
  /// built under admission (its bytes reserved, a compute slot held for the stream), then each chunk is read,
  /// decoded (INVALID_ARGUMENT naming the chunk and the point), computed on a compute thread in the arena and
  /// answered before the next is read: one chunk in memory, the client paused by flow control. A coordinator validates
  /// the header alike, then fans the chunks out to its replicas and merges their results back in the client's order
  /// (server/points_fan_out.h), admitted with the results it may hold.
  grpc::Status QueryPoints(grpc::ServerContext* context,
                           grpc::ServerReaderWriter<v1::PointsReply, v1::PointsRequest>* stream) override;

  /// With --peers: connects to the replicas (reads the --peer-* files); the service then coordinates (see
  /// server/tiled_query.h). Called once by the server before it serves.
  Status connectPeers();
  bool coordinating() const { return pool_ != nullptr; }

  void beginShutdown() { shutting_down_.store(true); }
  /// Cancels every running call (their Interrupters trip with `reason`).
  void stopAll(const Status& reason) { calls_.stopAll(reason); }
  int activeCalls() const { return calls_.active(); }
  int activeQueries() const { return slots_.active(); }
  AssetCache& cache() { return cache_; }
  MemoryBudget& budget() { return budget_; }
  const ActiveCalls& calls() const { return calls_; }
  const MemoryPlan& memoryPlan() const { return plan_; }

 private:
  /// Step 1 of the contract: admits the call (or says why not).
  Status admitCall(grpc::ServerContext* context, const char* method, std::unique_ptr<ActiveCalls::Call>* call);
  /// A compute slot, released when this goes out of scope.
  struct ComputeSlot {
    QuerySlots* slots = nullptr;
    ComputeSlot() = default;
    ComputeSlot(const ComputeSlot&) = delete;
    ComputeSlot& operator=(const ComputeSlot&) = delete;
    ~ComputeSlot() {
      if (slots) slots->release();
    }
  };
  /// Step 3: reserves `bytes` into `reservation` and a compute slot into `slot`, waiting at most --queue-wait-ms in
  /// total. On any error neither is held.
  Status admitWork(grpc::ServerContext* context, ActiveCalls::Call& call, uint64_t bytes, const std::string& what,
                   MemoryBudget::Reservation* reservation, ComputeSlot* slot);
  /// Step 4: runs `work` on a compute thread in the arena; the handler thread watches the context meanwhile.
  Status runCompute(grpc::ServerContext* context, ActiveCalls::Call& call, const std::function<Status()>& work);
  /// Steps 3 and 4 for work that reserves `bytes` while it runs (parsing an upload).
  Status computeAdmitted(grpc::ServerContext* context, ActiveCalls::Call& call, uint64_t bytes, const std::string& what,
                         const std::function<Status()>& work);

  /// Reads an upload stream into `data`. `on_header` checks the first chunk's header and gives the data size it
  /// promises (0: unknown). The buffer and its reservation in the memory budget grow with the bytes that arrive
  /// (a stalled client holds only what it sent), never past the promised size or --max-upload-bytes.
  template <typename Chunk>
  Status readUpload(grpc::ServerContext* context, grpc::ServerReader<Chunk>* reader, ActiveCalls::Call& call,
                    const char* what, const std::function<Status(const Chunk&, uint64_t*)>& on_header,
                    std::string* data, Chunk* first, MemoryBudget::Reservation* reservation);
  /// Parses a mesh under admission (budget + slot) and the call's Interrupter; `parse_seconds` (may be null) gets
  /// the parse's own time.
  Status parseMeshAdmitted(grpc::ServerContext* context, ActiveCalls::Call& call, std::string_view bytes,
                           v1::MeshFormat format, const std::string& name, std::string_view field,
                           std::shared_ptr<const Asset>* asset, double* parse_seconds);
  /// Puts a parsed upload into the asset cache; RESOURCE_EXHAUSTED naming `field` when `what` (e.g. "the volume") is
  /// larger than the whole cache.
  Status cacheUpload(const std::shared_ptr<const Asset>& asset, std::string_view field, std::string_view what);
  Status runQuery(grpc::ServerContext* context, ActiveCalls::Call& call, const v1::QueryRequest& request,
                  grpc::ServerWriter<v1::QueryReply>* writer, const RequestId& request_id, QueryRecord* record);
  /// An upload's reports to Metrics when its handler ends.
  void uploadEnded(Rpc rpc, const Status& status, const ActiveCalls::Call* call, uint64_t bytes, double seconds);
  Status runPoints(grpc::ServerContext* context, ActiveCalls::Call& call,
                   grpc::ServerReaderWriter<v1::PointsReply, v1::PointsRequest>* stream, const RequestId& rid,
                   const std::string& id);

  const ServerOptions options_;
  const ServerHooks hooks_;
  const std::unique_ptr<TokenAuth> auth_;
  const MemoryPlan plan_;
  Metrics& metrics_;
  std::unique_ptr<tbb::task_arena> arena_;
  std::unique_ptr<ReplicaPool> pool_;  ///< set when coordinating
  AssetCache cache_;
  MemoryBudget budget_;
  QuerySlots slots_;
  ActiveCalls calls_;
  std::atomic<bool> shutting_down_{false};
  std::atomic<uint64_t> next_query_{1};
};

}  // namespace distband
