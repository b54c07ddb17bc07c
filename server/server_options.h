// ServerOptions: everything an operator can tune on distband-server (each one is a command-line flag, see
// server/flags.h), plus ServerHooks, the in-process observation points tests and benches use.
// Contract: plain values; validate() returns "" or a message naming the flag and the rule. The resolved*()
// accessors turn "0 = automatic" settings into the values in force (the memory budget reads the process's memory
// limit: the cgroup's memory.max when set, else the machine's RAM).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include <grpcpp/support/status.h>

#include "core/status.h"

namespace distband {

struct ServerOptions {
  /// host:port; port 0 picks a free port. Loopback by default: exposing the service is an explicit decision
  /// (the container and the manifests pass 0.0.0.0:50051).
  std::string listen_address = "127.0.0.1:50051";
  /// Threads computing one query (the shared arena's workers + the query's own compute thread). 0 = all cores.
  int compute_threads = 0;
  int max_concurrent_queries = 4;      ///< queries (and upload parses) computing at once
  int queue_wait_ms = 2000;            ///< how long work beyond the slots or the memory budget waits
  uint64_t max_voxels_per_query = uint64_t(1024) * 1024 * 1024;  ///< bound on dims.x*dims.y*dims.z
  uint64_t max_upload_bytes = uint64_t(256) << 20;                ///< bound on one upload's data
  uint64_t max_triangles = uint64_t(1) << 24;  ///< bound on the triangles a mesh may declare or hold
  uint64_t max_vertices = uint64_t(1) << 24;   ///< bound on the vertices a mesh may declare or hold
  /// Asset cache capacity; 0 = a quarter of the memory budget (at most 1 GiB). Part of the memory budget.
  uint64_t cache_bytes = 0;
  /// Bytes the whole process may use for requests; 0 = half of the memory the process may use. Every upload and
  /// query is admitted by an estimate of its peak bytes against it.
  uint64_t memory_budget_bytes = 0;
  uint32_t max_message_bytes = 16u << 20;  ///< largest message received (inline seeds, upload chunks) or sent
  uint32_t batch_bytes = 1u << 20;         ///< default upper bound of one BrickBatch message
  /// Encoded messages one query may hold between its compute thread and its writer; the engine pauses beyond it.
  uint64_t stream_buffer_bytes = uint64_t(8) << 20;
  double grace_seconds = 10;  ///< on shutdown, how long running calls may continue before being cancelled
  /// An upload that receives nothing, or a query whose client consumes nothing, for this long is cancelled.
  double idle_timeout_seconds = 60;
  int max_streams = 128;     ///< concurrent RPCs of the DistanceField service; beyond it RESOURCE_EXHAUSTED at once
  int grpc_threads = 0;      ///< cap on gRPC's threads (its resource quota); 0 = max_streams + 16
  std::string tls_cert_file, tls_key_file;  ///< PEM; both set = TLS
  std::string tls_client_ca_file;           ///< PEM; set = clients must present a certificate it signed (mTLS)
  std::string auth_token_file;  ///< one bearer token a line; set = every DistanceField call needs one
  bool reflection = false;      ///< serve grpc.reflection.v1alpha (the schema is public, but off unless asked)
  /// IPV4:PORT or [IPV6]:PORT: serve Prometheus metrics at http://ADDR/metrics (server/metrics.h); empty = off.
  /// Its own port, no token: where it listens is its protection.
  std::string metrics_listen;

  // Coordinator (server/tiled_query.h): with `peers` set, queries are split into tiles computed by the replicas.
  std::string peers;             ///< gRPC target naming the replicas (server/replica_pool.h); empty = compute here
  uint64_t tile_voxels = uint64_t(1) << 24;  ///< largest tile (voxels); grids beyond it are split
  int tiles_in_flight_per_replica = 2;       ///< concurrent tile calls per replica
  int tile_retries = 3;                      ///< retries of a failed tile (on other replicas) before giving up
  double tile_timeout_seconds = 600;         ///< a tile call's own deadline (the client's, when sooner, wins)
  /// Bytes of later segments a query may hold while an earlier one waits for slow tiles (beyond: RESOURCE_EXHAUSTED).
  uint64_t tile_buffer_bytes = uint64_t(256) << 20;
  std::string peer_ca_file;     ///< PEM: reach the replicas over TLS, trusting this CA
  std::string peer_tls_name;    ///< name to check the replicas' certificates against (default: the address)
  std::string peer_token_file;  ///< first token of the file is sent to the replicas as the bearer token

  std::string validate() const;
  int resolvedComputeThreads() const;  ///< compute_threads, or the core count when 0
  uint64_t resolvedMemoryBudget() const;
  uint64_t resolvedCacheBytes() const;
  int resolvedGrpcThreads() const;
};

/// Reads a PEM file named by `flag` (errors name the flag and the file; a file without a PEM block is refused).
Status readPemFile(const std::string& path, const char* flag, std::string* out);

/// The memory this process may use: min(RAM, cgroup v2 memory.max / v1 memory.limit_in_bytes, RLIMIT_AS).
uint64_t processMemoryLimitBytes();

/// What happened to one query, reported when its handler ends (for tests, benches and the log line).
struct QueryRecord {
  using Clock = std::chrono::steady_clock;
  std::string id;
  std::string request_id;  ///< x-request-id (server/request_id.h)
  grpc::StatusCode code = grpc::StatusCode::OK;
  std::string message;
  bool engine_ran = false;        ///< the engine was started
  bool interrupted = false;       ///< the engine stopped early (cancel, disconnect, deadline, shutdown)
  Clock::time_point received{};   ///< handler entered
  Clock::time_point cancel_seen{};     ///< when the server noticed the cancel/disconnect (if it did)
  Clock::time_point engine_stopped{};  ///< computeBandField returned
  Clock::time_point finished{};        ///< handler about to return
  uint64_t voxels = 0, bricks = 0, messages = 0, bytes = 0;
  uint64_t reserved_bytes = 0;         ///< the memory-budget reservation it was admitted with
  int segments = 0;
  int tiles = 0, tile_retries = 0;     ///< a coordinator's query: tiles sent to replicas, attempts retried
};

struct ServerHooks {
  std::function<void(const QueryRecord&)> on_query_end;  ///< called on the handler thread; must be thread-safe
};

}  // namespace distband
