// ServerOptions: everything an operator can tune on distband-server (each one is a command-line flag, see
// server/flags.h), plus ServerHooks, the in-process observation points tests and benches use.
// Contract: plain values; validate() returns "" or a message naming the option and the rule.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include <grpcpp/support/status.h>

namespace distband {

struct ServerOptions {
  std::string listen_address = "0.0.0.0:50051";  ///< host:port; port 0 picks a free port
  /// Threads computing one query (the shared arena's workers + the query's own compute thread). 0 = all cores.
  int compute_threads = 0;
  int max_concurrent_queries = 4;      ///< queries computing at once
  int queue_wait_ms = 2000;            ///< how long a query beyond the limit waits before RESOURCE_EXHAUSTED
  uint64_t max_voxels_per_query = uint64_t(1024) * 1024 * 1024;  ///< bound on dims.x*dims.y*dims.z
  uint64_t max_upload_bytes = uint64_t(256) << 20;                ///< bound on one upload's data
  uint64_t cache_bytes = uint64_t(1) << 30;                       ///< asset cache capacity
  uint32_t max_message_bytes = 16u << 20;  ///< largest message received (inline seeds, upload chunks) or sent
  uint32_t batch_bytes = 1u << 20;         ///< default upper bound of one BrickBatch message
  /// Encoded messages one query may hold between its compute thread and its writer (the bounded queue).
  uint64_t stream_buffer_bytes = uint64_t(8) << 20;
  double grace_seconds = 10;  ///< on shutdown, how long running streams may continue before being cancelled

  std::string validate() const;
  int resolvedComputeThreads() const;  ///< compute_threads, or the core count when 0
};

/// What happened to one query, reported when its handler ends (for tests, benches and the log line).
struct QueryRecord {
  using Clock = std::chrono::steady_clock;
  std::string id;
  grpc::StatusCode code = grpc::StatusCode::OK;
  std::string message;
  bool engine_ran = false;        ///< the engine was started
  bool interrupted = false;       ///< the engine stopped early (cancel, disconnect, deadline, shutdown)
  Clock::time_point received{};   ///< handler entered
  Clock::time_point cancel_seen{};     ///< when the server noticed the cancel/disconnect (if it did)
  Clock::time_point engine_stopped{};  ///< computeDistanceField returned
  Clock::time_point finished{};        ///< handler about to return
  uint64_t voxels = 0, bricks = 0, messages = 0, bytes = 0;
  int segments = 0;
};

struct ServerHooks {
  std::function<void(const QueryRecord&)> on_query_end;  ///< called on the handler thread; must be thread-safe
};

}  // namespace distband
