// Metrics: what distband-server tells Prometheus, and MetricsEndpoint, which serves it (--metrics-listen ADDR:
// GET http://ADDR/metrics in the Prometheus text format). docs/operations.md lists every metric.
// Contract:
//   * One Metrics per server. The service, its query streams, admission, uploads and the coordinator's parts
//     (tile dispatcher, merger, replica pool) report to it; nothing in core/ knows it.
//   * Disabled (Metrics::disabled(), no --metrics-listen) it holds nothing and every report returns at once: the
//     hot path pays one predictable branch per report.
//   * Bounded: label values are RPC names, gRPC status code names, upload refusal reasons and, on a coordinator,
//     the replica addresses its --peers resolve to (an operator's list, at most kMaxReplicaLabels at once, beyond
//     that "other"; a replica that leaves the resolution loses its series). Never a per-request label: the size of a
//     scrape does not grow with the calls served.
//   * Scrape-time values (streams open, budget, asset cache, replicas) are read through the Sources given to
//     watch(), when Prometheus scrapes; the standard process_ family (CPU, memory, threads, fds) from /proc/self.
//   * Names follow Prometheus' conventions: distband_ prefix (the process_ family keeps its standard names),
//     base units in the name (seconds, bytes), counters end in _total.
//   * MetricsEndpoint listens on exactly the address given (its own port, never the gRPC listener's) and answers
//     /metrics without the bearer token; everything else is 404. Protect it by where it listens (loopback, a pod
//     address behind a NetworkPolicy), as docs/operations.md says.
// Thread-safe.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/support/status_code_enum.h>

#include "core/status.h"

namespace distband {

/// The RPCs of distband.v1.DistanceField: the `rpc` label's values.
enum class Rpc { kUploadMesh = 0, kUploadVolume, kQuery, kGetInfo, kQueryPoints };
inline constexpr int kRpcCount = 5;
const char* rpcName(Rpc rpc);

/// Why an upload was refused: the `reason` label's values.
enum class UploadRefusal {
  kAuth = 0,   ///< no or a wrong bearer token ("auth")
  kBadInput,   ///< a malformed stream or file ("bad_input")
  kLimits,     ///< --max-upload-bytes, --max-voxels, --max-triangles/--max-vertices, the cache, --max-streams
               ///< ("limits")
  kBudget,     ///< the memory budget or the compute slots stayed full for --queue-wait-ms ("budget")
};
inline constexpr int kUploadRefusalCount = 4;
const char* refusalName(UploadRefusal reason);

inline constexpr size_t kMaxReplicaLabels = 64;

class Metrics {
 public:
  /// What gauges read when Prometheus scrapes (each may be empty: that gauge is then not exported).
  struct Sources {
    std::function<double()> streams_open;             ///< DistanceField calls in flight
    std::function<double()> budget_reserved_bytes;    ///< reserved in the requests' memory budget
    std::function<double()> budget_bytes;             ///< the requests' memory budget
    std::function<double()> cache_bytes, cache_capacity_bytes, cache_entries;
    std::function<double()> compute_threads;
    std::function<double()> replicas_known, replicas_healthy;  ///< a coordinator's
  };

  static std::unique_ptr<Metrics> disabled();
  /// Every family registered in a fresh registry (and the process_ family).
  static std::unique_ptr<Metrics> enabled();
  ~Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;

  bool on() const { return impl_ != nullptr; }
  /// Registers the scrape-time gauges; call once, before serving. The sources must outlive every scrape.
  void watch(Sources sources);

  // Calls (every DistanceField handler, refused calls included).
  void callEnded(Rpc rpc, grpc::StatusCode code, double seconds);

  // Queries.
  void queryQueued(int delta);   ///< waiting for admission (budget, compute slot)
  void queryRunning(int delta);  ///< admitted, streaming
  void queryAdmitted(double queue_wait_seconds);
  void queryFirstBrick(double seconds_since_received);
  /// A query computed here (not a coordinator's) that ran to its end.
  void queryComputed(double seed_seconds, double compute_seconds);
  void querySentBytes(uint64_t bytes);
  void querySentVoxels(uint64_t voxels);

  // Uploads.
  void uploadReceived(Rpc rpc, uint64_t bytes);
  void uploadParsed(Rpc rpc, double seconds);
  void uploadRefused(Rpc rpc, UploadRefusal reason);

  // Coordinator. `replica` is the replica's address as gRPC names it ("ipv4:10.0.0.7:50051"; "" when the call never
  // reached one: "unknown").
  void tileDispatched(const std::string& replica);
  /// A tile attempt failed on `replica`; `retried`: the tile runs again elsewhere.
  void tileFailed(const std::string& replica, bool retried);
  /// The replicas the pool resolves to now: series of replicas no longer among them are dropped.
  void replicasResolved(const std::vector<std::string>& addresses);
  void mergeBufferChanged(int64_t delta_bytes);

  /// The exposition text a scrape returns (tests, the scrape-size check); "" when disabled.
  std::string text() const;

 private:
  friend class MetricsEndpoint;
  struct Impl;
  explicit Metrics(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The HTTP endpoint serving a Metrics' registry at /metrics.
class MetricsEndpoint {
 public:
  /// Listens on `address` (IPV4:PORT or [IPV6]:PORT; port 0 picks a free one). Fails (INVALID_ARGUMENT naming
  /// --metrics-listen) when the address is malformed or cannot be bound, or is IPv6 and civetweb was built without
  /// it (as Debian bookworm's is).
  static Status start(const std::string& address, Metrics& metrics, std::unique_ptr<MetricsEndpoint>* out);
  ~MetricsEndpoint();
  int port() const { return port_; }

 private:
  struct Impl;
  MetricsEndpoint() = default;
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
};

/// Whether `address` is a metrics address the endpoint accepts: an IPv4 literal or a bracketed IPv6 literal, a
/// colon and a port (digits, 0..65535). Host names and a bare port (all interfaces, by accident) are refused.
bool validMetricsAddress(const std::string& address, int* port = nullptr);

}  // namespace distband
