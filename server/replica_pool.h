// ReplicaPool: a coordinator's connections to its replicas (distband-server --peers TARGET).
// Contract:
//   * TARGET names every replica, either as a gRPC target — "ipv4:10.0.0.1:50051,10.0.0.2:50051",
//     "ipv6:[::1]:5001,...", "dns:///distband-headless.ns.svc.cluster.local:50051" (a Kubernetes headless Service:
//     one A record per pod) — or as a list of names, "replica1:50051,replica2:50051,..." (every address each name
//     resolves to; compose services, fixed hosts), which the pool resolves itself.
//   * balanced() is one channel over all of them with gRPC's round_robin policy: each tile is one call, so tiles
//     spread per call; a dead replica leaves the rotation by itself. gRPC re-resolves dns: targets; a list of names
//     is re-resolved by the pool (at most once a second, when replicas() is asked) and the channel rebuilt when the
//     addresses change.
//   * replicas() lists one channel per replica address (resolved now, at most every second: for uploads, which must
//     reach every replica because round_robin decides where each tile runs).
//   * prepare() adds the call credentials (--peer-token-file) and a deadline to a ClientContext. TLS to the
//     replicas with --peer-ca (and --peer-tls-name when certificates do not name the addresses).
//   * onResolved() hears every resolution that changes the addresses (the metrics drop a departed replica's
//     series); watchHealth() starts a thread that asks every replica's grpc.health.v1 service
//     ("distband.v1.DistanceField", 1 s deadline) each interval, for healthyReplicas(). Both are for the metrics and
//     set before the pool is used; the thread stops when the pool is destroyed.
// Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/status.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/server_options.h"

namespace distband {

class ReplicaPool {
 public:
  struct Replica {
    std::string address;  ///< a gRPC target naming exactly one replica, e.g. "ipv4:10.0.0.1:50051"
    std::shared_ptr<grpc::Channel> channel;
  };

  /// Reads the credential files named by the options (errors name the flag).
  static Status create(const ServerOptions& options, std::unique_ptr<ReplicaPool>* out);

  /// The round_robin stub (null while no replica address is known).
  std::shared_ptr<v1::DistanceField::Stub> balanced();
  /// Every replica the target names now (resolved at most once a second); empty when none resolves.
  std::vector<Replica> replicas();
  /// Replicas found by the last resolution.
  size_t lastReplicaCount() const;
  void prepare(grpc::ClientContext* context, std::chrono::system_clock::time_point deadline) const;
  const std::string& target() const { return target_; }

  using ResolvedCallback = std::function<void(const std::vector<std::string>& addresses)>;
  /// `callback` is called, under the pool's lock (it must not call the pool), after each resolution that changed
  /// the addresses.
  void onResolved(ResolvedCallback callback);
  void watchHealth(std::chrono::milliseconds interval);
  /// Replicas that answered SERVING at the last health round (0 before the first, or without watchHealth()).
  size_t healthyReplicas() const { return healthy_.load(); }

  ~ReplicaPool();

 private:
  ReplicaPool() = default;
  void healthRounds(std::chrono::milliseconds interval);
  std::shared_ptr<grpc::Channel> makeChannel(const std::string& target, bool round_robin) const;

  std::string target_;
  std::shared_ptr<grpc::ChannelCredentials> credentials_;
  std::string tls_name_, token_;
  int max_message_bytes_ = 0;
  bool name_list_ = false;  ///< TARGET is a list of names resolved here (else a gRPC target)
  std::string balanced_target_;
  std::shared_ptr<v1::DistanceField::Stub> balanced_stub_;
  mutable std::mutex mu_;
  std::chrono::steady_clock::time_point resolved_at_{};
  std::vector<Replica> replicas_;
  ResolvedCallback on_resolved_;
  std::atomic<size_t> healthy_{0};
  std::mutex health_mu_;
  std::condition_variable health_cv_;
  bool health_stop_ = false;
  std::thread health_thread_;
};

/// The calls one coordinated query makes to its replicas (a tiled query's tiles, a point query's streams, the seeds'
/// uploads of both): each is prepared alike (credentials, a deadline, the query's x-request-id) and cancelled with
/// the others when the query stops. TileDispatcher and PointsFanOut are ones; SeedShipper's uploads go through them.
class ReplicaCalls {
 public:
  /// Keeps `context` prepared and cancellable with the query's calls for its scope.
  class Call {
   public:
    Call(ReplicaCalls& calls, grpc::ClientContext* context) : calls_(calls), context_(context) {
      calls_.enroll(context_);
    }
    ~Call() { calls_.withdraw(context_); }
    Call(const Call&) = delete;
    Call& operator=(const Call&) = delete;

   private:
    ReplicaCalls& calls_;
    grpc::ClientContext* context_;
  };

  virtual ~ReplicaCalls() = default;
  /// Why calls must not start now (the query stopped or failed); OK while they may.
  virtual Status stopReason() const = 0;
  /// The query's request id (server/request_id.h), for the replicas and the log lines of its calls.
  virtual const std::string& requestId() const = 0;

 protected:
  /// Prepares `context` and cancels it with the query's calls until withdraw(context).
  virtual void enroll(grpc::ClientContext* context) = 0;
  virtual void withdraw(grpc::ClientContext* context) = 0;
};

/// The addresses a target names, each as a single-address gRPC target ("ipv4:a:p" / "ipv6:[a]:p"); DNS names are
/// resolved with getaddrinfo. Empty with `error` set when the target is malformed or nothing resolves.
std::vector<std::string> resolveReplicaAddresses(const std::string& target, std::string* error);

}  // namespace distband
